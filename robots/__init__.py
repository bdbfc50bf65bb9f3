"""Robot models and task builders (pinocchio): robot state -> hierarchy tasks."""
