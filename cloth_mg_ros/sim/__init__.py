"""The simulation: what a cloth is (`model`), how it steps (`integrator`, `explicit`), a garment
worn on a moving capsule body (`garment`: GarmentSim), its levels of detail (`detail`), the
tolerance each level solves to (`tolerance`) and the sheet scenes (`sheets`).

Below: physics (energies and their derivatives), mesh, collision, solvers, motion, io.
"""
