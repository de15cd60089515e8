"""cloth_mg_ros: a garment on a moving human body, stepped implicitly with a faithful multigrid,
for ROS 2.

The folders are the layers, lowest first; a module imports only from its own layer and those
above it in this list:

- `errors`: ClothInputError, the one exception bad input raises.
- `io`: bags of body poses, packaged files, pictures, text tables, ROS messages as bytes.
- `collision`: capsules, planes, discs, meshes and cloth-cloth contact.
- `mesh`: triangle meshes, the 1-to-4 subdivision hierarchy, garments cut on the body.
- `physics`: materials and the energies with their forces and Jacobians.
- `solvers`: the linear solvers of a step: the faithful multigrid and the baselines.
- `motion`: BVH motion capture, the capsule avatar and its poses.
- `sim`: the cloth model and its step, a garment on a moving body, grippers and the forces
  on what holds and touches the cloth, levels of detail, sheets.
- `budget`: what a scene may cost on this machine (cost model, tolerance calibration).
- `config`: the parameter schema and the scenes' params files.
- `apps`: whole jobs: the headless runner, batches, the cluster, the warm-up.
- `fidelity`: the textile tests (cantilever, tensile, Cusick drape).
- `ros`: the ROS 2 node and its tools (the only layer that imports rclpy, with bench and cli).
- `bench`: the benchmarks.
- `cli`: the `cloth-mg` command line.
"""
