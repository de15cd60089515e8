"""cloth_node's grasp services (`gripper/<name>/grasp`, std_srvs/SetBool), served off the
executor that ingests the body poses.

A grasp call is answered by the simulation thread before its next tick (ros.gripper_desk:
what a grasp takes depends on where the cloth is then), so its callback waits up to a tick.
Served by the node's own single-threaded executor, that wait would hold every pose arriving
meanwhile. The services therefore live on a second node of the same context and namespace,
`<node name>_grasp`, spun by its own executor on its own thread: a call waits there while the
poses go on arriving (rclpy cannot defer a service's response, and a coroutine callback that
awaits a future makes rclpy's executor spin without sleeping until it is done). That node
takes the node's namespace but not the process's remap rules (a global `__node:=` would give
it the node's own name).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

from rclpy.exceptions import InvalidServiceNameException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_srvs.srv import SetBool

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.executor import single_threaded_executor

__all__ = ["GraspServices"]

SPIN_PERIOD_S = 0.1  # s: how often the services' thread looks whether it should stop
JOIN_TIMEOUT_S = 15.0  # s: how long `close` waits for a call in progress


class GraspServices:
    """`gripper/<name>/grasp` for each name, on a node beside `node` (module docstring).

    answer(name, grasp) -> (success, message): the call's answer (it may wait for the
    simulation thread). ClothInputError when a name makes no valid service name.
    """

    def __init__(self, node: Node, names: Sequence[str],
                 answer: Callable[[str, bool], tuple[bool, str]]) -> None:
        # Not the process's --ros-args: a global `__node:=` remap would name it as `node`.
        self.node = Node(f"{node.get_name()}_grasp", namespace=node.get_namespace(),
                         context=node.context, use_global_arguments=False)
        self._answer = answer
        self.services = []
        try:
            for name in names:
                self.services.append(self.node.create_service(
                    SetBool, f"gripper/{name}/grasp",
                    lambda req, res, n=name: self._on_grasp(n, req, res)))
        except InvalidServiceNameException as exc:
            self.node.destroy_node()
            raise ClothInputError(f"parameter grippers: {name!r} makes no valid service "
                                  f"name ({exc})") from exc
        self._executor = single_threaded_executor(node.context)
        self._executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name="grasp services", daemon=True)
        self._thread.start()

    def _on_grasp(self, name: str, request: SetBool.Request, response: SetBool.Response
                  ) -> SetBool.Response:
        """true grasps what is in reach, false releases; the simulation thread answers."""
        response.success, response.message = self._answer(name, bool(request.data))
        return response

    def _spin(self) -> None:
        context = self.node.context
        while not self._stop.is_set() and context.ok():
            try:
                self._executor.spin_once(timeout_sec=SPIN_PERIOD_S)
            except ExternalShutdownException:
                break
            except Exception:
                if context.ok() and not self._stop.is_set():
                    raise
                break  # the context went down under the wait

    def close(self) -> None:
        """Stop serving (after a call in progress, which the stopped simulation answers at
        once) and destroy the services' node."""
        self._stop.set()
        self._thread.join(JOIN_TIMEOUT_S)
        if self._thread.is_alive():  # still in a call: destroying its node under it would crash
            self.node.get_logger().warning(
                f"the grasp services' thread did not stop within {JOIN_TIMEOUT_S:g} s (a call "
                f"still waiting); their node is left to the process's exit")
            return
        self._executor.remove_node(self.node)
        self._executor.shutdown(timeout_sec=0.0)
        self.node.destroy_node()
