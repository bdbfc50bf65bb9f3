// One thread at a time per prepared solver (extended_jacobian.cpp and the closed forms).
#pragma once

#include <atomic>

#include "prioik/extended_jacobian.hpp"

namespace prioik {

// Marks a solver busy for the scope of a solve; throws ConcurrentUse when another thread
// holds it.
class BusyGuard {
 public:
  explicit BusyGuard(std::atomic<bool>& busy) : busy_(busy) {
    if (busy_.exchange(true, std::memory_order_acquire))
      throw ConcurrentUse("a prepared solver serves one thread at a time: another thread is "
                          "solving with it");
  }
  ~BusyGuard() { busy_.store(false, std::memory_order_release); }
  BusyGuard(const BusyGuard&) = delete;
  BusyGuard& operator=(const BusyGuard&) = delete;

 private:
  std::atomic<bool>& busy_;
};

}  // namespace prioik
