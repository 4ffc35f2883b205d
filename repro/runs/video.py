"""Evaluation videos: MP4 (H.264) through the ffmpeg binary that the ``imageio-ffmpeg`` wheel ships; and the
final evaluation's frames (``frames.npz``, for the trajectory figure).

Frames are collected in memory during one evaluation episode and written atomically (a temporary file in the
same folder, then a rename), so a killed run never leaves a torn video under its final name.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from repro.config.schema import VideoEvery
from repro.runs.fsutil import atomic_output, atomic_write
from repro.runs.runformat import FRAMES
from repro.runs.runformat import VIDEOS as VIDEO_DIR

__all__ = ["VIDEO_DIR", "VIDEO_EVERY", "EvalVideos", "count_frames", "save_frames", "video_name", "write_mp4"]

VIDEO_EVERY = VideoEvery.values()


def video_name(index: int, unit: str = "frame") -> str:
    """``frame_000010000.mp4`` (online: the training frame of the evaluation; offline runs: ``update_...``),
    so a resumed run that repeats an evaluation overwrites its video with the same content."""
    return f"{unit}_{index:09d}.mp4"


@dataclass(frozen=True)
class EvalVideos:
    """Where and when a training loop writes evaluation videos (``train.save_video``)."""

    folder: Path  # {run}/videos
    size: int  # train.video_size
    every: str = "all"  # train.video_every: all | last
    unit: str = "frame"  # "frame" (online) or "update" (offline runs)
    fps: int = 30

    def __post_init__(self) -> None:
        if self.every not in VIDEO_EVERY:
            raise ValueError(f"video_every must be one of {', '.join(VIDEO_EVERY)} (got {self.every!r})")

    def wanted(self, final: bool) -> bool:
        """Whether the evaluation (``final``: the last one of the run) gets a video."""
        return self.every == VideoEvery.all or final

    def save(self, index: int, frames: np.ndarray | list[np.ndarray]) -> Path:
        return write_mp4(self.folder / video_name(index, self.unit), frames, fps=self.fps)


def write_mp4(path: str | os.PathLike, frames: np.ndarray | list[np.ndarray], fps: int = 30) -> Path:
    """Encode (T, H, W, 3) uint8 frames to ``path`` (H.264, yuv420p, so that every player opens it)."""
    import imageio_ffmpeg

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"expected (T, H, W, 3) uint8 frames, got {frames.shape} {frames.dtype}")
    if len(frames) == 0:
        raise ValueError("no frames to write")
    if frames.shape[1] % 2 or frames.shape[2] % 2:
        raise ValueError(f"H.264 (yuv420p) needs an even height and width, got {frames.shape[1:3]}")
    path = Path(path)
    height, width = frames.shape[1:3]
    with atomic_output(path, suffix=f".tmp{path.suffix}") as tmp:  # the encoder reads the container from the suffix
        writer = imageio_ffmpeg.write_frames(str(tmp), (width, height), fps=fps, codec="libx264",
                                             pix_fmt_out="yuv420p", macro_block_size=1,
                                             output_params=["-loglevel", "error"])
        writer.send(None)  # start the encoder
        try:
            for frame in frames:
                writer.send(np.ascontiguousarray(frame))
        finally:
            writer.close()
    return path


def count_frames(path: str | os.PathLike) -> int:
    """Decode ``path`` and count its frames (for tests and `repro` checks)."""
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    size = meta["size"][0] * meta["size"][1] * 3
    n = 0
    for chunk in reader:
        if len(chunk) != size:
            raise ValueError(f"{path}: a frame of {len(chunk)} bytes, expected {size}")
        n += 1
    return n


def save_frames(run_dir: str | os.PathLike, frames: np.ndarray) -> None:
    """Frames of one evaluation episode, uint8 (T, H, W, 3), as ``{run}/frames.npz``, compressed and written
    atomically."""

    def write(f) -> None:
        buf = io.BytesIO()
        np.savez_compressed(buf, frames=frames)
        f.write(buf.getvalue())

    atomic_write(Path(run_dir) / FRAMES, write)
