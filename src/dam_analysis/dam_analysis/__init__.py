"""Lift analysis for Detaching Assist Motion: SPCM kinematics, the sufficient lift condition, the
contact stiffness model, the /check_lift service and k_theta-delta_theta_p maps.
"""
