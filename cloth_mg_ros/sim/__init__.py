"""The simulation: what a cloth is (`model`), how it steps (`integrator`, `explicit`), a garment
worn on a moving capsule body (`garment_sim`: GarmentSim), its levels of detail (`detail`: the
rungs), the tolerance each rung solves to (`solve_tolerance`) and the sheet scenes (`sheets`).

Below: physics (energies and their derivatives), mesh, collision, solvers, motion, io.
"""
