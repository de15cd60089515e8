"""What a scene may cost on this machine: the cost model (`cost_model`: tick time against
particles, calibrated once per machine, choosing particles auto) and the tolerance each level
of detail's time step allows (`tolerance_rule`: its calibration).
"""
