"""Test cameras for the recorder: live 30 fps sources on a schedule, and the spec that opens
one in a camera process (classes at module level: the recorder pickles the spec)."""

from __future__ import annotations

import time

import cv2
import numpy as np

from pslog.records import NS

ORANGE_BGR = (20, 110, 255)


class ScheduledSource:
    """A live 30 fps camera drawing an orange ball that moves a pixel a frame; frame ``k`` is
    due :meth:`delay_s` after frame ``k``'s 30 fps slot. Subclasses say when it ends
    (:meth:`end`: return True for no more frames, or raise) and whether a frame is stamped
    with its due time or the time it was delivered (``stamp_due``)."""

    clock = "test clock"
    live = True
    stamp_due = True

    def __init__(self) -> None:
        self.k = 0
        self.t0 = time.monotonic_ns()

    def set_start(self, t0_ns: int) -> None:
        self.t0 = t0_ns

    def delay_s(self, k: int) -> float:
        return 0.0

    def end(self, k: int) -> bool:
        return False

    def read(self):
        if self.end(self.k):
            return None
        due = self.t0 + int((self.k / 30 + self.delay_s(self.k)) * NS)
        time.sleep(max(due - time.monotonic_ns(), 0) / NS)
        frame = np.full((480, 640, 3), (60, 120, 70), np.uint8)
        cv2.circle(frame, (300 + self.k, 200), 6, ORANGE_BGR, -1)
        self.k += 1
        stamp = due if self.stamp_due else time.monotonic_ns()
        return self.k - 1, stamp - self.t0, frame

    def close(self) -> None:
        pass


class Spec:
    """A camera of the recorder made of a test source class (picklable: the camera process
    opens it)."""

    width, height = 640, 480

    def __init__(self, source: type, text: str) -> None:
        self.source, self.text = source, text

    def describe(self) -> str:
        return self.text

    def open(self):
        return self.source()
