"""Run in a fresh process by test_warmup.py: warm a body scene up as the node does, then run
the scene's real tick path on a bag (dressing on its first pose, ticks of one and of several
poses, a teleport, every level of detail and back) and print, as JSON, how many kernel
signatures the real path still compiled or loaded after the warm-up (0: the warm-up was
complete).

usage: python warmup_check.py SCENE PARTICLES BAG_DIR"""

import json
import sys

import numpy as np

from cloth_mg_ros.apps.warmup import CompileWatch, kernel_signatures, warm_up_garment
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.io.bags import read_pose_frames
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim

scene, particles, bag = sys.argv[1], int(sys.argv[2]), sys.argv[3]
params = load_scene(scene)
options = BodySimOptions.from_scene(params, particles=particles, tolerance=1e-2, threads=2)
material = get_material(params.material)
avatar = Avatar.load()
warm, _ = warm_up_garment(avatar, material, options, lod=True)
before = kernel_signatures()
with CompileWatch() as watch:
    frames = read_pose_frames(bag, "/avatar/body_poses")
    garment_sim = GarmentSim.dress(avatar, frames[0][0], frames[0][1], material, options)
    garment_sim.advance(frames[1:4])  # a tick that coalesced three poses
    for stamp, poses in frames[4:-6]:
        garment_sim.advance([(stamp, poses)])
    stamp, poses = frames[-6]
    jumped = np.array(poses)
    jumped[:, 0] += 3.0
    garment_sim.reanchor(stamp, jumped)
    levels = garment_sim.rung_indices()
    garment_sim.prepare_rungs()
    for level, (stamp, poses) in zip([*levels[1:], levels[0]] * 2, frames[-5:],
                                    strict=False):
        jumped = np.array(poses)
        jumped[:, 0] += 3.0
        garment_sim.set_rung(level)
        garment_sim.advance([(stamp, jumped)])
    finite = bool(np.isfinite(garment_sim.positions).all())
print(json.dumps({"warm_ms": warm.ms, "warm_compiled": warm.compiled,
                  "after": kernel_signatures() - before, "compiled_after": watch.compiled,
                  "levels": levels, "finite": finite}))
