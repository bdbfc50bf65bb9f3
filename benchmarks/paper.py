"""What Jeong & Chang (2009) report, for the pages that set measurements beside it.

Keyed by registry formulation: the method of the paper each one implements.
"""

#: per-control-step computation times of Sec. III-B.3 (ms; 28-DOF humanoid, 4 tasks,
#: 2.4 GHz Pentium)
STEP_TIMES_MS = {"extended_jacobian": 1.4, "nullspace": 2.7, "unifying": 3.2,
                 "operational_space": 4.8}

#: the paper's names of the methods
METHOD_NAMES = {"extended_jacobian": "proposed framework (extended Jacobian)",
                "nullspace": "resolved acceleration method",
                "unifying": "unifying framework",
                "operational_space": "operational space formulation"}
