"""Import an external dataset layout into a dataset folder, and export a dataset folder to one."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from repro.data.dataset import MIN_FRAME, DatasetError, Manifest, iter_episodes, load_manifest, write_dataset
from repro.data.formats import get_format
from repro.envs import UnknownTaskError, get_task

IMPORTED_KIND = "imported"


def default_import_name(fmt: str) -> str:
    """The folder name under ``{results_root}/datasets/{task}/`` when ``--out`` is not given."""
    return f"imported-{fmt}"


def import_dataset(path: str | Path, fmt: str, task: str, out: str | Path, resize: int | None = None) -> Manifest:
    """Check ``path``'s layout completely, then write it as a dataset at ``out`` (resumable).

    The task must be known and its action dimension must match the files'. The frames must have the format's
    documented size (vd4rl-64: 64x64, the others 84x84) unless ``resize`` (``--resize N``) asks for NxN
    frames, made by bicubic interpolation and recorded in the manifest's source. A folder this call created
    is removed again if the input turns out to be damaged half-way; a partial import it resumed is kept.
    """
    form = get_format(fmt)
    try:
        info = get_task(task)
    except UnknownTaskError as exc:
        raise DatasetError(str(exc)) from None
    src = Path(path).expanduser().absolute()
    scan = form.scan(src)
    if scan.action_dim != info.action_dim:
        raise DatasetError(f"wrong action dim: {src} holds actions of dim {scan.action_dim}, task {task} has "
                           f"{info.action_dim} (another task's data?)")
    size = (form.size, form.size)
    if resize is None and tuple(scan.image_size) != size:
        raise DatasetError(f"wrong frame size: {src} holds {scan.image_size[0]}x{scan.image_size[1]} frames, "
                           f"format {fmt} is {size[0]}x{size[1]}; pass --resize N to resize them to NxN (bicubic)")
    if resize is not None and resize < MIN_FRAME:
        raise DatasetError(f"--resize {resize}: a run needs frames of at least {MIN_FRAME}x{MIN_FRAME}")
    source = {"format": fmt, "path": str(src), "files": len({u.file for u in scan.units}),
              "episodes": scan.episodes, "transitions": scan.transitions, "image_size": list(scan.image_size),
              **scan.details}
    if resize is not None:
        source.update({"resized_to": resize, "interpolation": "bicubic (Pillow)", "resized_on_request": True})
    out = Path(out)
    created = not out.exists()
    try:
        return write_dataset(out, form.read(scan, resize), task=task, kind=IMPORTED_KIND, source=source, rule={})
    except DatasetError:
        if created:
            shutil.rmtree(out, ignore_errors=True)
        raise


def export_dataset(directory: str | Path, fmt: str, out: str | Path) -> list[Path]:
    """Write a complete dataset in ``fmt`` to the new folder ``out`` (staged beside it, renamed at the end)."""
    form = get_format(fmt)
    load_manifest(directory)
    out = Path(out)
    if out.exists():
        raise DatasetError(f"{out} already exists; export writes a new folder only")
    stage = out.parent / f".{out.name}.partial"
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    try:
        files = form.write(iter_episodes(directory), stage)
        os.replace(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return [out / f.name for f in files]
