"""ROS topic names as the node, the recorder, the player and the bag writer accept them.

Written here rather than taken from rclpy: the bag tools run without ROS (the core never
imports rclpy), and a name rclpy would refuse must be refused before a bag is written or a
recording waits for it (rclpy raises only when the publisher or subscription is made).
"""

from __future__ import annotations

__all__ = ["is_absolute_topic"]


def is_absolute_topic(name: str) -> bool:
    """Whether `name` is an absolute ROS topic name: '/', then /-separated parts of letters,
    digits and _, each starting with a letter or _ ('/cloth/marker', '/a/b_1'; not '/',
    '/a/', '/a b', '/1a', '/a,/b')."""
    return (isinstance(name, str) and name.startswith("/")
            and all(part and (part[0].isalpha() or part[0] == "_")
                    and all(c.isascii() and (c.isalnum() or c == "_") for c in part)
                    for part in name[1:].split("/")))
