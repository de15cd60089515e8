"""The node's pose ingestion (ros.ingest) in process: stale frames, frames out of order, new
time lines and resets, with nothing lost: every valid pose is used, pending, skipped as
stale, or discarded by a reset."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy")

from log_lines import LogLines
from node_harness import pose_array_cdr

from cloth_mg_ros.motion.frames import FrameStatus
from cloth_mg_ros.ros.ingest import NEW_STREAM_KEYS, FrameLog, PoseIngest


def _ingest(frames) -> tuple[PoseIngest, list]:
    restarts: list = []
    segments = len(frames[0][1])
    ingest = PoseIngest(segments, 1.0, FrameLog(LogLines(), segments),
                        on_restart=lambda prev, new: restarts.append((prev, new)))
    return ingest, restarts


def _offer(ingest: PoseIngest, stamp: float, poses: np.ndarray) -> FrameStatus | None:
    return ingest.offer(pose_array_cdr(round(stamp * 1e9), poses))


def _take(ingest: PoseIngest) -> list[tuple[float, int]]:
    return [(round(k.stamp, 6), k.generation) for k in ingest.take()]


def test_one_stale_frame_is_skipped_and_the_stream_goes_on(walk_frames):
    ingest, restarts = _ingest(walk_frames)
    poses = walk_frames[0][1]
    for k in range(10):
        assert _offer(ingest, 10.0 + k / 30, poses) == FrameStatus.OK
    assert len(_take(ingest)) == 10
    # One message stamped 5 s in the past among the live stream: stale, no new stream.
    assert _offer(ingest, 5.0, poses) == FrameStatus.STALE
    for k in range(10, 20):
        assert _offer(ingest, 10.0 + k / 30, poses) == FrameStatus.OK
    keys = _take(ingest)
    assert [g for _, g in keys] == [0] * 10 and restarts == []
    c = ingest.counts()
    assert ingest.frames.counts["stale"] == 1 and c.skipped == 1 and c.restarts == 0
    assert c.received == 21 and c.pending == 0


def test_frames_out_of_order_are_used_while_ahead_of_the_simulated_time(walk_frames):
    ingest, restarts = _ingest(walk_frames)
    stamps = [s for s, _ in walk_frames[:8]]
    poses = [p for _, p in walk_frames[:8]]
    for i in (0, 2, 1, 3):  # 1 arrives after 2: both still ahead of the simulation
        assert _offer(ingest, stamps[i], poses[i]) == FrameStatus.OK
    assert [s for s, _ in _take(ingest)] == [round(s, 6) for s in stamps[:4]]
    for i in (5, 6):
        _offer(ingest, stamps[i], poses[i])
    assert _offer(ingest, stamps[4], poses[4]) == FrameStatus.OK  # late, still ahead
    assert [s for s, _ in _take(ingest)] == [round(s, 6) for s in stamps[4:7]]
    # Behind the simulated time (6 was taken), or a stamp already received: stale.
    assert _offer(ingest, stamps[5], poses[5]) == FrameStatus.STALE
    _offer(ingest, stamps[7], poses[7])
    assert _offer(ingest, stamps[7], poses[7]) == FrameStatus.STALE  # a duplicate
    assert [s for s, _ in _take(ingest)] == [round(stamps[7], 6)]
    _offer(ingest, stamps[7] + 0.1, poses[7])
    assert restarts == [] and ingest.frames.counts["stale"] == 2


def test_a_new_time_line_starts_after_several_frames_and_loses_none(walk_frames):
    ingest, restarts = _ingest(walk_frames)
    late = 10.0  # s: a bag's end, before it starts over
    (s0, p0), (s1, p1) = walk_frames[:2]
    _offer(ingest, s0 + late, p0)
    _offer(ingest, s1 + late, p1)
    # The stamps go back by 10 s and go on from there: a looped bag. Until NEW_STREAM_KEYS
    # frames have gone on, they wait (pending); then the old stream's buffered keys come
    # first and the new one is generation 1 from its first frame.
    for i in range(NEW_STREAM_KEYS):
        s, p = walk_frames[2 + i]
        expected = FrameStatus.OK if i == NEW_STREAM_KEYS - 1 else FrameStatus.STALE
        assert _offer(ingest, s, p) == expected
        if i < NEW_STREAM_KEYS - 1:
            assert ingest.counts().pending == 2 + i + 1 and restarts == []
    assert restarts == [(pytest.approx(s1 + late), pytest.approx(walk_frames[2][0]))]
    keys = _take(ingest)
    assert [g for _, g in keys] == [0, 0] + [1] * NEW_STREAM_KEYS
    c = ingest.counts()
    assert c.skipped == 0 and c.discarded == 0 and c.restarts == 1 and c.pending == 0
    assert ingest.live_from == 0


def test_a_second_publisher_interleaved_with_the_live_one_never_restarts(walk_frames):
    ingest, restarts = _ingest(walk_frames)
    poses = walk_frames[0][1]
    for k in range(40):  # the same clip 2 s behind, interleaved message by message
        _offer(ingest, 10.0 + k / 30, poses)
        _take(ingest)
        _offer(ingest, 8.0 + k / 30, poses)
    ingest.close()
    assert restarts == [] and ingest.frames.counts["stale"] == 40
    assert ingest.counts().pending == 0


def test_a_reset_discards_the_buffered_and_the_waiting_frames(walk_frames):
    ingest, _ = _ingest(walk_frames)
    poses = walk_frames[0][1]
    _offer(ingest, 10.0, poses)
    _take(ingest)
    _offer(ingest, 10.1, poses)
    _offer(ingest, 3.0, poses)  # stale, waiting to see whether a time line follows
    ingest.reset()
    c = ingest.counts()
    assert c.discarded == 2 and c.pending == 0 and ingest.live_from == ingest.generation == 1
    assert _offer(ingest, 0.5, poses) == FrameStatus.OK  # stamps may start over
    assert _take(ingest) == [(0.5, 1)]


def test_a_pose_in_another_frame_than_the_streams_is_skipped_until_a_reset(walk_frames):
    """A second publisher (or a tracker that switched frames) on the topic: its poses are
    skipped and counted as wrong_frame, not woven into the body's path; a pose naming no
    frame is taken; after ~/reset the stream may start in the new frame."""
    ingest, _ = _ingest(walk_frames)
    poses = walk_frames[0][1]

    def offer(stamp: float, frame_id: str) -> FrameStatus | None:
        return ingest.offer(pose_array_cdr(round(stamp * 1e9), poses, frame_id))

    assert offer(10.0, "world") == FrameStatus.OK
    assert offer(10.1, "camera") == FrameStatus.WRONG_FRAME
    assert offer(10.2, "") == FrameStatus.OK
    assert ingest.frames.counts["wrong_frame"] == 1 and ingest.counts().skipped == 1
    ingest.reset()
    assert offer(1.0, "camera") == FrameStatus.OK
    assert offer(1.1, "world") == FrameStatus.WRONG_FRAME


def test_the_counts_add_up_at_every_snapshot_and_a_lost_pose_shows(walk_frames):
    """PoseCounts.lost (cloth/stats' `dropped`) is received minus every count: 0 at any
    snapshot, also while frames are being checked on another thread, and 1 once a taken key
    is never counted."""
    import threading

    ingest, _ = _ingest(walk_frames)
    poses = walk_frames[0][1]
    sent = 400

    def publish() -> None:
        for k in range(sent):
            if k % 7 == 3:
                ingest.offer(b"\x00\x01")  # malformed: skipped on receipt
            elif k % 11 == 5:
                _offer(ingest, 1.0 + k / 30, poses)  # stale
            else:
                _offer(ingest, 20.0 + k / 30, poses)

    publisher = threading.Thread(target=publish)
    publisher.start()
    used = 0
    while publisher.is_alive() or ingest.counts().pending:
        assert ingest.counts().lost(0) == 0
        keys = ingest.take()
        assert ingest.counts().lost(len(keys)) == 0  # taken: in the simulation's hands
        ingest.used(len(keys))
        used += len(keys)
    publisher.join()
    ingest.close()
    c = ingest.counts()
    assert c.received == sent and c.lost(0) == 0 and c.used == used
    # every valid pose used, every bad one skipped under its own kind
    malformed = sum(k % 7 == 3 for k in range(sent))
    stale = sum(k % 7 != 3 and k % 11 == 5 for k in range(sent))
    assert used == sent - malformed - stale and c.skipped == malformed + stale
    assert {k: v for k, v in ingest.frames.counts.items() if v} == {"malformed": malformed,
                                                                     "stale": stale}
    _offer(ingest, 100.0, poses)
    ingest.take()  # taken and never counted
    assert ingest.counts().lost(0) == 1
