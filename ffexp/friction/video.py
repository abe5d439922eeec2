"""Reading videos for the friction tracker: grey frames from OpenCV with a
read-ahead thread, and the array types the trackers share.

Pixel ``(u, v)`` has its centre at integer ``(u, v)`` (OpenCV convention).
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
from collections.abc import Callable, Generator, Iterator
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
import numpy.typing as npt

from drivers.config import not_regular
from ffexp.errors import InputError

GreyF = npt.NDArray[np.float32]
Grey8 = npt.NDArray[np.uint8]
#: A decoded frame: BGR (h, w, 3) or grey (h, w).
Frame = npt.NDArray[np.uint8]

#: ``progress(frames_done, frames_total_or_0)``.
ProgressFn = Callable[[int, int], None]

#: How tracking ended.
TrackEnd = Literal["end_of_video", "left_frame", "lost", "still"]


@contextlib.contextmanager
def quiet_opencv() -> Iterator[None]:
    """Silence OpenCV's own logging (decoder warnings on stderr) for a while."""
    old = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(old)


class VideoFrames:
    """Grey frames of a video read with ``cv2.VideoCapture``.

    Raises:
        InputError: the file is missing or OpenCV cannot decode it.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        odd = not_regular(path)
        if odd:
            raise InputError(f"{path}: is {odd}, not a regular video file")
        if path.is_dir():
            raise InputError(f"{path}: is a directory, expected a video file")
        if not path.is_file():
            raise InputError(f"{path}: no such file")
        with quiet_opencv():
            cap = cv2.VideoCapture(str(path))
            if not cap.isOpened():
                raise InputError(f"{path}: cannot read video (OpenCV cannot open it)")
            ok, first = cap.read()
        if not ok or first is None:
            cap.release()
            raise InputError(f"{path}: cannot read video (no decodable frame)")
        self._cap = cap
        self._first: npt.NDArray[np.uint8] | None = np.asarray(first, np.uint8)
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        self.fps = fps if math.isfinite(fps) and fps > 0 else 0.0
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count = max(count, 0)
        self.size = (int(first.shape[1]), int(first.shape[0]))

    def __iter__(self) -> Generator[Frame, None, None]:
        """Decoded frames as OpenCV returns them (BGR, or grey).

        Decoding runs in a read-ahead thread (OpenCV releases the GIL while
        decoding), so that it overlaps with tracking.
        """
        frames: queue.Queue[Frame | None] = queue.Queue(maxsize=8)
        stop = threading.Event()

        def read_ahead() -> None:
            try:
                while not stop.is_set():
                    ok, nxt = self._cap.read()
                    if not ok or nxt is None:
                        break
                    while not stop.is_set():
                        try:
                            frames.put(np.asarray(nxt, np.uint8), timeout=0.1)
                            break
                        except queue.Full:
                            continue
            finally:
                while not stop.is_set():
                    try:
                        frames.put(None, timeout=0.1)
                        break
                    except queue.Full:
                        continue

        first = self._first
        self._first = None
        if first is None:
            return
        with quiet_opencv():
            worker = threading.Thread(target=read_ahead, name="ffexp-video-read", daemon=True)
            worker.start()
            try:
                yield first
                while (frame := frames.get()) is not None:
                    yield frame
            finally:
                stop.set()
                while worker.is_alive():
                    try:
                        frames.get(timeout=0.05)
                    except queue.Empty:
                        pass
                worker.join()
                self.close()

    def close(self) -> None:
        """Release the decoder."""
        self._cap.release()


def to_grey(frame: Frame) -> Grey8:
    if frame.ndim == 2:
        return frame
    if frame.shape[2] == 1:
        return frame[:, :, 0]
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)  # type: ignore[return-value]
