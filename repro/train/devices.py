"""The devices a run asks for (``runtime.device``, ``replay.device``, ``dataset make --device``), checked against
this machine before anything is written."""

from __future__ import annotations

import torch

from repro.config.errors import UserError
from repro.config.schema import Device


class DeviceError(UserError, ValueError):
    """A device name that is unknown or not present on this machine (one line)."""


def resolve_device(name: str, key: str = "device") -> str:
    """``auto`` -> cuda when available, else cpu; ``cpu``/``cuda``/``cuda:N`` as given when present.

    Raises :class:`DeviceError` (one line, naming ``key``) for another name or a CUDA device this machine
    lacks, before anything is written."""
    name = str(name)  # a Device member (runtime.device, replay.device) or a plain name such as cuda:1
    if name == Device.auto:
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == Device.cpu:
        return name
    if name == Device.cuda or (name.startswith("cuda:") and name[5:].isdigit()):
        if not torch.cuda.is_available():
            raise DeviceError(f"{key}={name}: this machine has no CUDA device (torch sees none); use cpu or auto")
        if ":" in name and int(name[5:]) >= torch.cuda.device_count():
            raise DeviceError(f"{key}={name}: this machine has {torch.cuda.device_count()} CUDA device(s)")
        return name
    raise DeviceError(f"{key}={name}: unknown device; one of auto, cpu, cuda, cuda:N")
