"""Frame sources of ``labauto track SOURCE``: a video file, a folder of images, a camera plugin.

Each source is an iterator of ``(name, image)`` frames that raises :class:`SourceError` (one
line naming the source, what went wrong and how many frames came before) instead of ending
quietly, so the command can keep what it already printed and stop with one clear line:

* a **video file**: read with OpenCV's ``VideoCapture``; a file it cannot open, or one that
  opens but yields no frame, is an error; frames end at the end of the file;
* a **folder**: its image files (``.png .jpg .jpeg .bmp .tif .tiff``) in name order, each read
  by :func:`labauto.imageio.read_image`; an empty folder, or an unreadable file on the way, is
  an error;
* a **camera plugin**, ``camera:NAME``: the ``camera`` driver ``NAME`` registered by a plugin,
  built from the config's ``camera`` section. Its frames are taken in a background thread: a
  camera that raises, or delivers nothing for ``frame_timeout_s``, is an error.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from labauto.errors import LabautoError

__all__ = ["IMAGE_SUFFIXES", "SourceError", "open_source"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
CAMERA_PREFIX = "camera:"

Frames = Iterator[tuple[str, np.ndarray]]


class SourceError(LabautoError):
    """A frame source failed (the message names it and the frames delivered before)."""


def open_source(
    source: str,
    *,
    camera_factory: Callable[[str], Iterable[tuple[str, np.ndarray]]] | None = None,
    frame_timeout_s: float = 10.0,
) -> Frames:
    """The frames of ``source`` (see the module docstring).

    Parameters
    ----------
    source : str
        A video file, a folder, or ``camera:NAME``.
    camera_factory : callable, optional
        ``camera_factory(NAME) -> iterable of (name, image)``, for ``camera:NAME``.
    frame_timeout_s : float
        Longest wait for a camera's next frame.
    """
    if source.startswith(CAMERA_PREFIX):
        name = source.removeprefix(CAMERA_PREFIX)
        if camera_factory is None:
            raise SourceError(f"{source}: no camera drivers available")
        return camera_frames(source, camera_factory(name), frame_timeout_s)
    path = Path(source)
    if path.is_dir():
        return folder_frames(path)
    if path.is_file():
        return video_frames(path)
    raise SourceError(f"{source}: no such video file or folder (a camera is camera:NAME)")


def folder_frames(folder: Path) -> Frames:
    """The images of ``folder`` in name order."""
    from labauto.imageio import read_image

    files = sorted(
        p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
    )
    if not files:
        raise SourceError(f"{folder}: folder has no images ({', '.join(IMAGE_SUFFIXES)})")

    def frames() -> Frames:
        for index, file in enumerate(files):
            try:
                image = read_image(file)
            except LabautoError as exc:
                raise SourceError(f"{exc} (after {index} frames of {folder})") from None
            yield file.name, image

    return frames()


def video_frames(path: Path) -> Frames:
    """The frames of a video file."""
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        capture.release()
        raise SourceError(f"{path}: cannot open as a video (not a video file, or no codec)")
    ok, first = capture.read()
    if not ok or first is None:
        capture.release()
        raise SourceError(f"{path}: video has no readable frame")

    def frames() -> Frames:
        try:
            image, index = first, 0
            while True:
                yield f"{path.name}#{index}", image
                ok, image = capture.read()
                if not ok or image is None:
                    return
                index += 1
        finally:
            capture.release()

    return frames()


def camera_frames(
    source: str, camera: Iterable[tuple[str, np.ndarray]], frame_timeout_s: float
) -> Frames:
    """A camera's frames, taken in a thread so a camera that stops delivering is noticed."""
    items: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=4)
    stop = threading.Event()

    def offer(item: tuple[str, Any]) -> bool:
        """Queue ``item`` unless the reader has stopped; False when it has."""
        while not stop.is_set():
            try:
                items.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for frame in camera:
                if not offer(("frame", frame)):
                    return
            offer(("end", None))
        except Exception as exc:
            offer(("error", exc))

    thread = threading.Thread(target=produce, name="labauto-track-camera", daemon=True)
    thread.start()

    def frames() -> Frames:
        count = 0
        try:
            while True:
                try:
                    kind, value = items.get(timeout=frame_timeout_s)
                except queue.Empty:
                    raise SourceError(
                        f"{source}: camera delivered no frame for {frame_timeout_s:g} s "
                        f"(after {count} frames)"
                    ) from None
                if kind == "end":
                    return
                if kind == "error":
                    raise SourceError(
                        f"{source}: camera failed after {count} frames: "
                        f"{type(value).__name__}: {value}"
                    )
                name, image = value
                count += 1
                yield str(name), image
        finally:
            stop.set()

    return frames()
