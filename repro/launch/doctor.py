"""``repro doctor``: what would break a run on the machine it gets, checked before a sweep spends anything.

Each check is ``ok``, ``warn`` (shown; the runs can go) or ``fail`` (they cannot), in one line:

- ``render``: MuJoCo renders one frame of each suite the sweep's tasks use, with ``$MUJOCO_GL`` (egl unless set),
  in a child process (a broken EGL can crash the process that loads it), and says on what (EGL device, GL renderer);
- ``gpu``: ``MUJOCO_EGL_DEVICE_ID`` and ``CUDA_VISIBLE_DEVICES`` name the same GPU: their PCI bus ids when both are
  known (EGL's DRM device, CUDA's device 0 through nvidia-smi), the two indexes otherwise;
- ``cuda``: the runs' ``runtime.device`` is on this machine (``cuda``: torch sees a GPU; ``auto`` on a machine with a
  GPU allocated but a torch that sees none would train on the CPU);
- ``results root``: it exists (or its nearest existing parent does) and is writable;
- ``dataset``: each dataset the sweep reads: every episode file's sha256 matches its manifest;
- ``versions``: torch (and its CUDA), mujoco, dm-control and metaworld beside their pins (``requirements.txt``; a
  version outside ``pyproject.toml``'s range fails).

``repro sweep --launcher slurm`` runs :func:`preflight_job` as one short job with the sweep's cluster config first
(``repro/launch/slurm.py``) and submits the grid only when no check fails.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

if TYPE_CHECKING:
    from repro.launch.spec import PlannedRun

OK, WARN, FAIL = "ok", "warn", "fail"
RENDER_TIMEOUT_S = 120  # a child that renders one frame per suite; a hung EGL initialisation is a failure
DEFAULT_TASK = "cheetah_run"
PINNED = ("torch", "mujoco", "dm-control", "metaworld")  # the packages printed beside their pins
DIST = "taco-repro"  # this project's distribution (its declared requirements: pyproject.toml)
REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Check:
    name: str  # render | gpu | cuda | results root | dataset | versions
    status: str  # ok | warn | fail
    detail: str

    def line(self) -> str:
        return f"{self.status:<4}  {self.name:<12}  {self.detail}"


@dataclass(frozen=True)
class DoctorInputs:
    """What the runs of a sweep need from the machine they get (pickled into the preflight job)."""

    results_root: str
    tasks: tuple[str, ...] = (DEFAULT_TASK,)  # rendered: one task per suite the sweep uses
    devices: tuple[str, ...] = ("auto",)  # the runs' runtime.device values
    datasets: tuple[tuple[str, str], ...] = ()  # (label, folder) of each dataset the runs read


@dataclass
class DoctorReport:
    """The checks and where they ran."""

    host: str
    checks: list[Check]
    job_id: str | None = None
    env: dict[str, str] = field(default_factory=dict)  # MUJOCO_GL, CUDA_VISIBLE_DEVICES, MUJOCO_EGL_DEVICE_ID

    @property
    def failed(self) -> list[Check]:
        return [c for c in self.checks if c.status == FAIL]

    def to_json(self) -> dict[str, Any]:
        return {"host": self.host, "job_id": self.job_id, "env": self.env, "checks": [asdict(c) for c in self.checks]}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> DoctorReport:
        return cls(str(data["host"]), [Check(**c) for c in data["checks"]], data.get("job_id"), dict(data["env"]))


ENV_SHOWN = ("MUJOCO_GL", "CUDA_VISIBLE_DEVICES", "MUJOCO_EGL_DEVICE_ID")


def inputs_for(planned: Sequence[PlannedRun], root: Path) -> DoctorInputs:
    """The doctor's inputs for the runs of a sweep that are to run (not done, not waiting for their dataset), and
    the datasets of every run not done (one not made yet is a warning: its runs wait)."""
    from repro.envs import get_task

    todo = [p for p in planned if p.state != "done" and not p.waiting] or list(planned)
    tasks: dict[str, str] = {}
    for p in todo:
        tasks.setdefault(str(get_task(p.run.task).suite), p.run.task)
    devices = sorted({str(p.cfg.runtime.device) for p in todo})
    datasets = {str(p.need.path): p.need.label() for p in planned if p.need is not None and p.state != "done"}
    return DoctorInputs(str(root), tuple(tasks.values()) or (DEFAULT_TASK,), tuple(devices) or ("auto",),
                        tuple((label, path) for path, label in sorted(datasets.items())))


def run_checks(inputs: DoctorInputs) -> DoctorReport:
    """Every check, in this process's environment (and a child's for the rendering)."""
    os.environ.setdefault("MUJOCO_GL", "egl")  # as the runs (repro_app/cli.py, the SLURM job)
    rendering = start_render_probe(inputs.tasks)  # renders while this process imports torch
    torch_info = _torch_info()
    probe = rendering.result()
    checks = [render_check(probe), gpu_check(dict(os.environ), probe.get("egl"), torch_info.get("pci")),
              cuda_check(inputs.devices, torch_info, os.environ.get("CUDA_VISIBLE_DEVICES")),
              results_root_check(Path(inputs.results_root))]
    checks += [dataset_check(label, Path(path)) for label, path in inputs.datasets]
    checks.append(versions_check(torch_info))
    env = {k: os.environ[k] for k in ENV_SHOWN if k in os.environ}
    return DoctorReport(socket.gethostname(), checks, os.environ.get("SLURM_JOB_ID"), env)


def preflight_job(inputs: DoctorInputs) -> dict[str, Any]:
    """The preflight SLURM job (submitit): the checks on the node, in the environment a run's job gets there."""
    cpus = os.environ.get("SLURM_CPUS_PER_TASK")
    if cpus:
        os.environ.setdefault("OMP_NUM_THREADS", cpus)
    report = run_checks(inputs)
    for c in report.checks:
        print(c.line(), flush=True)  # the job's log holds every check
    return report.to_json()


# ------------------------------------------------------------------------------------------------ rendering

@dataclass
class RenderProbe:
    """A child process rendering one frame of each task (``python -m repro.launch.doctor --render TASK...``)."""

    tasks: tuple[str, ...]
    process: subprocess.Popen

    def result(self) -> dict[str, Any]:
        """``{"gl": ..., "frames": {task: [seconds, std, shape]}, "renderer": ..., "egl": {...}}``, or with
        ``"error"``: one line."""
        try:
            stdout, stderr = self.process.communicate(timeout=RENDER_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.communicate()
            return {"error": f"rendering {', '.join(self.tasks)} did not finish in {RENDER_TIMEOUT_S} s (a hung EGL "
                             "or GL driver)"}
        lines = [ln for ln in stdout.splitlines() if ln.startswith("{")]
        if lines:
            return dict(json.loads(lines[-1]))
        code = self.process.returncode
        why = f"killed by signal {-code}" if code < 0 else f"exit {code}"
        tail = [ln for ln in stderr.splitlines() if ln.strip()]
        return {"error": f"the rendering process died ({why})" + (f": {tail[-1].strip()}" if tail else "")}


def start_render_probe(tasks: Sequence[str]) -> RenderProbe:
    cmd = [sys.executable, "-m", "repro.launch.doctor", "--render", *tasks]
    process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=str(REPO) if (REPO / "repro").is_dir() else None)
    return RenderProbe(tuple(tasks), process)


def render_probe(tasks: Sequence[str]) -> dict[str, Any]:
    """Render one frame of each task in a child process (a broken EGL may crash the process that loads it)."""
    return start_render_probe(tasks).result()


def _probe_main(tasks: Sequence[str]) -> int:
    """``python -m repro.launch.doctor --render TASK...``: one JSON line on stdout."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    result: dict[str, Any] = {"gl": os.environ["MUJOCO_GL"], "frames": {}}
    try:
        from repro.envs import make_env

        for task in tasks:
            start = time.perf_counter()
            env = make_env(task, seed=1, image_size=84)
            frame = env.reset(1).observation
            result["frames"][task] = [round(time.perf_counter() - start, 2), float(frame.std()),
                                      "x".join(map(str, frame.shape))]
            env.close()
    except Exception as exc:  # any failure of the backend's import, context or rendering: one line
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(json.dumps({**result, "error": f"{type(exc).__name__}: {msg}"}))
        return 1
    result["renderer"] = _gl_renderer()
    if result["gl"] == "egl":
        result["egl"] = _egl_device()
    print(json.dumps(result))
    return 0


def _gl_renderer() -> str | None:
    """The GL_RENDERER of a context of MuJoCo's backend (e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``)."""
    try:
        from dm_control import _render
        from OpenGL import GL

        ctx = _render.Renderer(max_width=8, max_height=8)
        try:
            with ctx.make_current() as current:
                name = current.call(GL.glGetString, GL.GL_RENDERER)
        finally:
            ctx.free()
        return name.decode() if isinstance(name, bytes) else str(name)
    except Exception:  # informative only
        return None


EGL_DEVICE_EXT, EGL_EXTENSIONS, EGL_DRM_DEVICE_FILE_EXT = 0x322C, 0x3055, 0x3233


def _egl_device() -> dict[str, Any]:
    """The EGL device dm_control's display is on: its index among the EGL devices, their number, its extensions
    (``EGL_MESA_device_software``: the CPU) and, through its DRM device file, its PCI bus id (None when unknown)."""
    import ctypes

    try:
        from dm_control._render.pyopengl import egl_renderer

        lib = ctypes.CDLL("libEGL.so.1")
        proc = lib.eglGetProcAddress
        proc.restype, proc.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
        vp = ctypes.c_void_p
        query_display = ctypes.CFUNCTYPE(ctypes.c_uint, vp, ctypes.c_int, ctypes.POINTER(vp))(
            proc(b"eglQueryDisplayAttribEXT"))
        query_string = ctypes.CFUNCTYPE(ctypes.c_char_p, vp, ctypes.c_int)(proc(b"eglQueryDeviceStringEXT"))
        query_devices = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(vp), ctypes.POINTER(ctypes.c_int))(
            proc(b"eglQueryDevicesEXT"))
        device = vp()
        if not query_display(ctypes.cast(egl_renderer.EGL_DISPLAY, vp).value, EGL_DEVICE_EXT, ctypes.byref(device)):
            return {}
        found = (vp * 64)()
        count = ctypes.c_int()
        query_devices(64, found, ctypes.byref(count))
        devices = [found[i] for i in range(count.value)]
        extensions = (query_string(device.value, EGL_EXTENSIONS) or b"").decode().split()
        drm = query_string(device.value, EGL_DRM_DEVICE_FILE_EXT) if "EGL_EXT_device_drm" in extensions else None
        pci = None
        if drm:
            sysfs = Path("/sys/class/drm") / Path(drm.decode()).name / "device"
            pci = os.path.basename(os.path.realpath(sysfs)) if sysfs.exists() else None
        return {"index": devices.index(device.value) if device.value in devices else None, "count": len(devices),
                "software": "EGL_MESA_device_software" in extensions, "drm": drm.decode() if drm else None, "pci": pci}
    except Exception:  # informative: the gpu check falls back to the indexes
        return {}


def render_check(probe: dict[str, Any]) -> Check:
    gl = probe.get("gl", os.environ.get("MUJOCO_GL", "egl"))
    if "error" in probe:
        return Check("render", FAIL, f"MuJoCo cannot render with MUJOCO_GL={gl}: {probe['error']}")
    blank = [t for t, (_, std, _) in probe["frames"].items() if std == 0.0]
    if blank:
        return Check("render", FAIL, f"MUJOCO_GL={gl} renders blank frames for {', '.join(blank)} (every pixel equal)")
    frames = ", ".join(f"{t} {shape} in {s:.1f} s" for t, (s, _, shape) in probe["frames"].items())
    on = [f"MUJOCO_GL={gl}"]
    egl = probe.get("egl") or {}
    if egl.get("index") is not None:
        on.append(f"EGL device {egl['index']} of {egl['count']}" + (f" (PCI {egl['pci']})" if egl.get("pci") else ""))
    if probe.get("renderer"):
        on.append(str(probe["renderer"]))
    if egl.get("software"):
        on.append("software rendering, on the CPU")
    return Check("render", OK, f"{frames} ({', '.join(on)})")


# ------------------------------------------------------------------------------------------------ GPUs

def _pci(bus_id: str | None) -> str | None:
    """A PCI bus id as ``dddd:bb:dd.f`` in lower case (nvidia-smi writes ``00000000:3B:00.0``)."""
    if not bus_id:
        return None
    m = re.fullmatch(r"(?:([0-9a-fA-F]+):)?([0-9a-fA-F]{2}):([0-9a-fA-F]{2})\.([0-7])", bus_id.strip())
    if not m:
        return None
    domain = int(m.group(1) or "0", 16)
    return f"{domain:04x}:{m.group(2).lower()}:{m.group(3).lower()}.{m.group(4)}"


def gpu_check(env: dict[str, str], egl: dict[str, Any] | None, cuda_pci: str | None) -> Check:
    """MUJOCO_EGL_DEVICE_ID and CUDA_VISIBLE_DEVICES against each other: by the PCI bus ids of the GPU EGL renders on
    (``egl``, from the render probe) and of CUDA's device 0 (``cuda_pci``) when both are known, else by the ids."""
    cvd = env.get("CUDA_VISIBLE_DEVICES", "").strip()
    egl_id = env.get("MUJOCO_EGL_DEVICE_ID", "").strip()
    said = ", ".join(f"{k}={v}" for k, v in (("CUDA_VISIBLE_DEVICES", cvd), ("MUJOCO_EGL_DEVICE_ID", egl_id)) if v)
    egl = egl or {}
    egl_pci = _pci(egl.get("pci"))
    cuda_pci = _pci(cuda_pci)
    if egl_pci and cuda_pci:
        if egl_pci == cuda_pci:
            return Check("gpu", OK, f"EGL renders on the GPU CUDA uses (PCI {cuda_pci}; {said or 'neither set'})")
        return Check("gpu", FAIL, f"EGL renders on the GPU at PCI {egl_pci} (EGL device {egl.get('index')}), CUDA uses "
                     f"the one at {cuda_pci} ({said or 'neither set'}): set MUJOCO_EGL_DEVICE_ID to the EGL device of "
                     "CUDA's GPU")
    if cvd and egl.get("software"):
        return Check("gpu", WARN, f"{said}, but EGL renders on the CPU (software device {egl.get('index')}): "
                     "every frame is rendered without the GPU (no NVIDIA EGL library on this machine?)")
    if not cvd or not egl_id:
        return Check("gpu", OK, said + " (one set: nothing to compare)" if said else "neither CUDA_VISIBLE_DEVICES "
                     "nor MUJOCO_EGL_DEVICE_ID set")
    first = cvd.split(",")[0].strip()
    if first == egl_id:
        return Check("gpu", OK, f"{said}: the same index (PCI bus ids unknown here)")
    return Check("gpu", FAIL, f"{said}: EGL renders on device {egl_id}, CUDA computes on {first}; set "
                 f"MUJOCO_EGL_DEVICE_ID={first} (sweeps/launchers/example.yaml: export "
                 "MUJOCO_EGL_DEVICE_ID=${CUDA_VISIBLE_DEVICES%%,*})")


def _torch_info() -> dict[str, Any]:
    """torch's version, its CUDA, the GPUs it sees and the PCI bus id of device 0 (nvidia-smi, by its uuid)."""
    try:
        import torch
    except Exception as exc:  # a torch that does not import fails the versions check
        return {"error": f"{type(exc).__name__}: {exc}"}
    info: dict[str, Any] = {"version": torch.__version__, "cuda": torch.version.cuda, "count": 0}
    try:
        if torch.cuda.is_available():
            info["count"] = torch.cuda.device_count()
            props = torch.cuda.get_device_properties(0)
            info["name"] = props.name
            info["pci"] = _nvidia_smi_pci(str(getattr(props, "uuid", "")))
    except Exception as exc:  # a broken driver: torch imports but CUDA does not start
        info["cuda_error"] = " ".join(str(exc).split())
    return info


def _nvidia_smi_pci(uuid: str) -> str | None:
    if not uuid or shutil.which("nvidia-smi") is None:
        return None
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=uuid,pci.bus_id", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    want = uuid.lower().removeprefix("gpu-")
    for line in out.splitlines():
        got, _, bus = line.partition(",")
        if got.strip().lower().removeprefix("gpu-") == want:
            return bus.strip()
    return None


def cuda_check(devices: Sequence[str], torch_info: dict[str, Any], cvd: str | None) -> Check:
    """The runs' runtime.device values against the GPUs torch sees."""
    seen = int(torch_info.get("count", 0))
    sees = (f"torch sees {seen} GPU(s)" if seen else "torch sees no GPU") + (
        f" ({torch_info['name']})" if torch_info.get("name") else "")
    if torch_info.get("cuda_error"):
        sees = f"CUDA does not start: {torch_info['cuda_error']}"
    cpu_torch = "" if torch_info.get("cuda") else f" (torch {torch_info.get('version')} is a CPU-only build)"
    wanted = [d for d in devices if d.startswith("cuda")]
    if wanted and not seen:
        return Check("cuda", FAIL, f"runtime.device={wanted[0]} but {sees}{cpu_torch}")
    for d in wanted:
        if ":" in d and int(d.split(":")[1]) >= seen:
            return Check("cuda", FAIL, f"runtime.device={d} but {sees}")
    given = (cvd or "").strip()
    allocated = bool(given) and given not in ("-1", "NoDevFiles")  # SLURM's value when a job has no GPU
    if "auto" in devices and allocated and not seen:
        return Check("cuda", FAIL, f"a GPU is allocated (CUDA_VISIBLE_DEVICES={cvd}) but {sees}{cpu_torch}: "
                     "runtime.device=auto would train on the CPU")
    if allocated and tuple(devices) == ("cpu",):
        return Check("cuda", WARN, f"a GPU is allocated (CUDA_VISIBLE_DEVICES={cvd}) but the runs train on the CPU "
                     "(runtime.device=cpu)")
    uses = "the GPU" if seen and ("auto" in devices or wanted) else "the CPU"
    return Check("cuda", OK, f"runtime.device={','.join(devices)}: {sees}; the runs train on {uses}")


# ------------------------------------------------------------------------------------------------ files

def results_root_check(root: Path) -> Check:
    """The results root is a folder this process can write, or can make (repro/runs/fsutil.py's one rule); an
    existing one also takes a file (written, removed: a shared filesystem may refuse what its modes allow)."""
    from repro.runs.fsutil import OutputPathError, writable_folder

    try:
        writable_folder(root, "results root")
    except OutputPathError as exc:
        return Check("results root", FAIL, str(exc))
    if not root.is_dir():
        return Check("results root", OK, f"{root} can be made here (it does not exist yet)")
    try:
        with tempfile.NamedTemporaryFile(dir=root, prefix=".repro-doctor-"):
            pass
    except OSError as exc:
        return Check("results root", FAIL, f"results root {root} is not writable here ({exc.strerror or exc})")
    return Check("results root", OK, f"{root} writable")


def dataset_check(label: str, folder: Path) -> Check:
    """Every episode file of the dataset at ``folder`` hashes to its manifest's sha256."""
    from repro.data.dataset import SHA256_MISMATCH, DatasetError, episode_digest, listing_problems, load_manifest

    try:
        manifest = load_manifest(folder)
    except DatasetError as exc:
        if not folder.exists():
            return Check("dataset", WARN, f"{label} at {folder} not made yet: its runs wait (not submitted)")
        return Check("dataset", FAIL, f"{label} at {folder}: {exc}")
    problems = listing_problems(folder, manifest)
    start, size = time.perf_counter(), 0
    for entry in manifest.episodes:
        path = folder / entry.file
        try:
            digest = episode_digest(path)
            size += path.stat().st_size
        except OSError as exc:
            problems.append(f"{entry.file}: {exc.strerror or exc}")
            continue
        if digest != entry.sha256:
            problems.append(f"{entry.file}: {SHA256_MISMATCH}")
    if problems:
        more = f" (+{len(problems) - 1} more)" if len(problems) > 1 else ""
        return Check("dataset", FAIL, f"{label} at {folder}: {problems[0]}{more}")
    return Check("dataset", OK, f"{label}: {len(manifest.episodes)} episode files match their sha256 "
                 f"({size / 1e6:.0f} MB in {time.perf_counter() - start:.1f} s)")


# ------------------------------------------------------------------------------------------------ versions

def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def pins() -> tuple[dict[str, str], dict[str, str]]:
    """(requirements.txt's specifier, pyproject's) of each package of :data:`PINNED` (absent when unknown)."""
    from packaging.requirements import InvalidRequirement, Requirement

    def parse(lines: Sequence[str]) -> dict[str, str]:
        out: dict[str, str] = {}
        for line in lines:
            try:
                req = Requirement(line.split("#")[0].strip())
            except InvalidRequirement:
                continue
            if _norm(req.name) in PINNED and not req.marker:
                out[_norm(req.name)] = str(req.specifier)
        return out

    req_file = REPO / "requirements.txt"
    from_file = parse(req_file.read_text().splitlines()) if req_file.exists() else {}
    try:
        from importlib.metadata import PackageNotFoundError, requires

        declared = parse(requires(DIST) or [])
    except PackageNotFoundError:
        declared = {}
    return from_file, declared


def versions_check(torch_info: dict[str, Any]) -> Check:
    from importlib.metadata import PackageNotFoundError, version

    from packaging.specifiers import SpecifierSet
    from packaging.version import InvalidVersion, Version

    pinned, declared = pins()
    parts, bad, off = [], [], []
    for name in PINNED:
        try:
            have = torch_info["version"] if name == "torch" and "version" in torch_info else version(name)
        except PackageNotFoundError:
            parts.append(f"{name} missing")
            bad.append(f"{name} is not installed")
            continue
        pin = pinned.get(name) or declared.get(name) or ""
        shown = f"{name} {have}" + (f" (CUDA {torch_info.get('cuda') or 'none'})" if name == "torch" else "")
        parts.append(shown + (f" [pin {pin}]" if pin else ""))
        try:
            v = Version(have)
            if name in declared and not SpecifierSet(declared[name]).contains(v, prereleases=True):
                bad.append(f"{name} {have} outside {declared[name]} (pyproject.toml)")
            elif name in pinned and not SpecifierSet(pinned[name]).contains(v, prereleases=True):
                off.append(f"{name} {have} is not the tested {pinned[name]} (requirements.txt)")
        except InvalidVersion:
            off.append(f"{name} {have}: not a version")
    if "error" in torch_info:
        bad.insert(0, f"torch does not import: {torch_info['error']}")
    status, why = (FAIL, bad) if bad else (WARN, off) if off else (OK, [])
    return Check("versions", status, ("; ".join(why) + ": " if why else "") + ", ".join(parts))


# ------------------------------------------------------------------------------------------------ the command

def summary(report: DoctorReport) -> str:
    """One line: the failed checks (name: detail), or what passed."""
    if report.failed:
        return "; ".join(f"{c.name}: {c.detail}" for c in report.failed)
    warns = [c.name for c in report.checks if c.status == WARN]
    return f"{len(report.checks)} checks passed" + (f" ({len(warns)} warning(s): {', '.join(warns)})" if warns else "")


def cli_inputs(name: str | None, tasks: str | None, sets: Sequence[str] | None,
               results_root: Path | None) -> DoctorInputs:
    """The doctor's inputs for ``repro doctor [SWEEP]``: the sweep's runs (as ``repro sweep`` expands them with the
    same options), or without one a run of ``--tasks`` (default cheetah_run) with ``--set``'s config."""
    from repro.launch import spec as specs

    sel = specs.selection(tasks, None, None, sets, results_root)
    if name is not None:
        planned = specs.plan(specs.expand(specs.load(name), sel))
        return inputs_for(planned, specs.results_root_of(planned))
    from repro.config.compose import compose

    cfg = compose(list(sel.sets))
    return DoctorInputs(str(Path(str(cfg.runtime.results_root)).expanduser().absolute()),
                        tuple(sel.tasks or (DEFAULT_TASK,)), (str(cfg.runtime.device),))


def register(app: Any) -> None:
    """Add ``repro doctor`` to ``app``."""
    import typer

    @app.command("doctor")
    def doctor_cmd(
        name: Optional[str] = typer.Argument(None, help="A sweep (name or YAML): check what its runs need (one "
                                             "task per suite rendered, its datasets, its results root)."),
        tasks: Optional[str] = typer.Option(None, "--tasks", help="Comma-separated tasks instead of the sweep's."),
        sets: Optional[list[str]] = typer.Option(None, "--set", help="Config override key=value (repeatable)."),
        results_root: Optional[Path] = typer.Option(None, "--results-root", "--results", "-r",
                                                    help="Results root the runs write (default: the config's)."),
    ) -> None:
        """What would break a run on this machine: MuJoCo rendering (EGL device), MUJOCO_EGL_DEVICE_ID against
        CUDA_VISIBLE_DEVICES, runtime.device against the GPUs torch sees, the results root, each dataset's sha256, and
        torch/CUDA/mujoco/dm-control/metaworld beside their pins. Exit 1 when a check fails. `repro sweep --launcher
        slurm` runs it as a job first (docs/sweeps.md)."""
        from rich.markup import escape

        from repro.runs.console import console, fail

        report = run_checks(cli_inputs(name, tasks, sets, results_root))
        con = console()
        con.print(f"repro doctor on {report.host}" + "".join(f", {k}={v}" for k, v in report.env.items()),
                  highlight=False)
        style = {OK: "green", WARN: "yellow", FAIL: "red"}
        for c in report.checks:
            con.print(f"[{style[c.status]}]{c.status:<4}[/]  {c.name:<12}  {escape(c.detail)}", highlight=False)
        if report.failed:
            fail(summary(report), code=1)
        con.print(summary(report), highlight=False)


if __name__ == "__main__" and sys.argv[1:2] == ["--render"]:
    sys.exit(_probe_main(sys.argv[2:] or [DEFAULT_TASK]))
