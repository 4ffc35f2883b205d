"""Evaluation videos: MP4 (H.264) through the ffmpeg binary that the ``imageio-ffmpeg`` wheel ships.

Frames are collected in memory during one evaluation episode and written atomically (a temporary file in the
same folder, then a rename), so a killed run never leaves a torn video under its final name.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

VIDEO_DIR = "videos"


def video_name(frame: int) -> str:
    """``frame_000010000.mp4``: named by the training frame of the evaluation, so a re-run overwrites it."""
    return f"frame_{frame:09d}.mp4"


def write_mp4(path: str | os.PathLike, frames: np.ndarray | list[np.ndarray], fps: int = 30) -> Path:
    """Encode (T, H, W, 3) uint8 frames to ``path`` (H.264, yuv420p, so that every player opens it)."""
    import imageio_ffmpeg

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"expected (T, H, W, 3) uint8 frames, got {frames.shape} {frames.dtype}")
    if len(frames) == 0:
        raise ValueError("no frames to write")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    height, width = frames.shape[1:3]
    writer = imageio_ffmpeg.write_frames(str(tmp), (width, height), fps=fps, codec="libx264",
                                         pix_fmt_out="yuv420p", macro_block_size=1,
                                         output_params=["-loglevel", "error"])
    writer.send(None)  # start the encoder
    try:
        for frame in frames:
            writer.send(np.ascontiguousarray(frame))
    finally:
        writer.close()
    os.replace(tmp, path)
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
