"""repro/bench/results.py, the one owner of `repro bench`'s files: the files earlier versions wrote still read, today's
round-trip, one vocabulary of speed-up paths (``fast`` included, from the config or its recorded FastPlan) and one FPS
for every reader."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from repro.bench import results as br
from repro.config.compose import compose, typed

# Files as earlier versions of `repro bench` wrote them (format 1: no kind, the online agent under "algo")
OLD_ONLINE = {"hardware": "AMD EPYC (2 threads)", "device": "cpu", "host": "h", "results": [
    {"algo": "taco", "batch_size": 256, "speedup": "plain", "update_seconds": 2.0, "fps_estimate": 2.0, "repeats": 2},
    {"algo": "drqv2", "batch_size": 256, "update_seconds": 0.5, "fps_estimate": 8.0}],
    "e2e": [{"algo": "taco", "batch_size": 8, "profile": "tiny", "speedup": "plain", "phase_sync": True,
             "frames": 200, "seconds": 80.0, "phases": {"update": 60.0}, "fps": 2.5}],
    "ratios": {"taco_b256_over_drqv2_b256": 4.0}}
OLDEST_ONLINE = {"hardware": {"device": "cuda:NVIDIA A100", "cpu": "x"}, "results": [
    {"algo": "taco", "batch_size": 1024, "update_seconds": 0.25, "fps": 12.0}]}  # no speedup, fps, hardware object
OLD_OFFLINE = {"hardware": "CPU", "device": "cpu", "task": "cheetah_run", "results": [
    {"agent": "drqv2", "learner": "actor_critic", "batch_size": 256, "own_batch": False, "update_seconds": 0.4},
    {"agent": "cql", "learner": "cql", "batch_size": 256, "own_batch": False, "update_seconds": 0.8,
     "over_drqv2": 2.0}]}
OLD_ROOFLINE = {"hardware": "CPU", "device": "cpu", "roofline": [{"algo": "taco", "batch_size": 256}]}
OLD_DATA = {"hardware": "CPU", "device": "cpu", "transitions": 100, "offline_batches_per_s": 5.0}


def _write(folder: Path, name: str, data: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(json.dumps(data))
    return path


def test_files_of_earlier_versions_read_as_typed_entries(tmp_path):
    online = br.read(_write(tmp_path, "bench-h-cpu.json", OLD_ONLINE))
    assert online.kind == br.ONLINE and online.device == "cpu" and online.hardware == "AMD EPYC (2 threads)"
    taco, drq = online.updates
    assert (taco.agent, taco.batch_size, taco.path, taco.update_seconds) == ("taco", 256, "plain", 2.0)
    assert taco.frames_per_update == 4.0 and taco.extra["repeats"] == 2  # fps_estimate x update_seconds
    assert (drq.path, drq.fps) == ("plain", 8.0)  # no speedup: plain; its own printed estimate kept
    (e2e,) = online.e2e
    assert (e2e.agent, e2e.profile, e2e.fps) == ("taco", "tiny", 2.5)
    assert online.rest["ratios"] == {"taco_b256_over_drqv2_b256": 4.0}
    oldest = br.read(_write(tmp_path, "bench-h-cuda.json", OLDEST_ONLINE))
    assert oldest.device == "cuda" and oldest.hardware == "NVIDIA A100 (GPU)"  # from the file name, the object
    assert oldest.updates[0].fps == pytest.approx(12.0) and oldest.updates[0].frames_per_update == pytest.approx(3.0)
    offline = br.read(_write(tmp_path, "bench-offline-h-cpu.json", OLD_OFFLINE))
    assert offline.kind == br.OFFLINE and [e.agent for e in offline.offline] == ["drqv2", "cql"]
    assert br.offline_seconds(offline, "cql", 256) == 0.8 and br.offline_seconds(offline, "iql", 256) is None
    assert br.read(_write(tmp_path, "bench-roofline-h-cpu.json", OLD_ROOFLINE)).kind == br.ROOFLINE
    data = br.read(_write(tmp_path, "bench-offline-data-h.json", OLD_DATA))
    assert data.kind == br.DATA and data.data == br.DataEntry(100, offline_batches_per_s=5.0)


def test_todays_files_round_trip_and_say_their_kind(tmp_path):
    for data in (OLD_ONLINE, OLDEST_ONLINE, OLD_OFFLINE, OLD_ROOFLINE, OLD_DATA):
        first = br.parse(data)
        again = br.parse(json.loads(json.dumps(first.to_json())))
        assert again == first and again.to_json()["format"] == br.FORMAT and again.to_json()["kind"] == first.kind
    written = br.parse(OLD_ONLINE).to_json()
    assert all("agent" in r and "algo" not in r for r in [*written["results"], *written["e2e"]])  # one agent key
    assert all("path" in r and "speedup" not in r for r in [*written["results"], *written["e2e"]])  # the field's key


@pytest.mark.parametrize("data, needle", [
    ([1, 2], "not an object"),
    ({"results": [{"algo": "taco", "batch_size": 8}]}, "update_seconds"),
    ({"results": [{"algo": "taco", "batch_size": 8, "update_seconds": 0}]}, "must be positive"),
    ({"results": [{"algo": "taco", "batch_size": 8, "update_seconds": 1, "speedup": "turbo"}]}, "'turbo'"),
    ({"results": {}}, "no 'results' list"),
])
def test_a_bad_file_is_one_line_naming_it(tmp_path, data, needle):
    path = _write(tmp_path, "bench-h-cpu.json", data)
    with pytest.raises(br.BenchFormatError) as info:
        br.read(path)
    assert needle in str(info.value) and str(path) in str(info.value) and "\n" not in str(info.value)
    (tmp_path / "bench-h-cpu.json").write_text("{")
    with pytest.raises(br.BenchFormatError, match="cannot read"):
        br.read(path)


def test_the_path_a_run_trains_with_is_the_bench_vocabulary():
    assert list(br.PATH_FLAGS) == list(br.PATHS)  # `repro bench` times exactly the paths a run can train with
    for path, flags in br.PATH_FLAGS.items():
        assert br.path_of(typed(compose(["agent=taco", *flags])).agent) == path
    # agent.fast wins over what else is on (its FastPlan, resolved on the device, may hold amp and compile)
    both = typed(compose(["agent=taco", "agent.fast=true", "agent.amp=true", "agent.compile=true"])).agent
    assert br.path_of(both) == "fast"
    assert br.path_of({"amp": True}) == "amp" and br.path_of({}, fast={"amp": True, "u8_shift": True}) == "fast"


def test_one_fps_the_loop_as_it_trains_first_then_the_update_bound():
    bench = br.parse({"device": "cpu", "results": [
        {"agent": "taco", "batch_size": 8, "speedup": "plain", "update_seconds": 0.5, "frames_per_update": 4},
        {"agent": "taco", "batch_size": 8, "speedup": "fast", "update_seconds": 0.125, "frames_per_update": 4}],
        "e2e": [{"agent": "taco", "batch_size": 8, "speedup": "plain", "frames": 100, "seconds": 50.0},
                {"agent": "taco", "batch_size": 8, "speedup": "plain", "phase_sync": False, "frames": 100,
                 "seconds": 25.0}]})
    assert br.rate(bench, "taco", 8, "plain") == br.Rate(4.0, br.E2E)  # phase_sync false: what a run sees
    assert br.rate(bench, "taco", 8, "fast") == br.Rate(32.0, br.UPDATE_BOUND)  # 4 frames / 0.125 s
    assert br.rate(bench, "taco", 8, "fast", frames_per_update=8).fps == 64.0  # the run's own frames per update
    assert br.rate(bench, "taco", 8, "amp") is None and br.rate(bench, "drqv2", 8) is None
    assert br.settings(bench) == [("taco", 8, "plain"), ("taco", 8, "fast")]


def test_the_newest_online_file_names_the_device(tmp_path):
    folder = tmp_path / "bench"
    assert br.newest_device(folder) is None
    cuda = _write(folder, "bench-h-cuda.json", OLDEST_ONLINE)
    cpu = _write(folder, "bench-h-cpu.json", OLD_ONLINE)
    _write(folder, "bench-offline-h-cpu.json", OLD_OFFLINE)
    os.utime(cuda, (1, 1))
    assert br.newest_device(folder) == "cpu" and br.files(folder) == [cpu, cuda]
    os.utime(cpu, (0, 0))
    assert br.newest_device(folder) == "cuda" and br.files(folder, br.ONLINE, "cpu") == [cpu]
    assert [p.name for p in br.files(folder, br.OFFLINE)] == ["bench-offline-h-cpu.json"]


def test_a_run_is_labelled_with_the_path_it_trained_with(tmp_path):
    """The speed tables labelled every run 'plain': a run with agent.fast is now its own source ('[fast]'), and the
    claim `speed`, which keeps the plain path only, no longer mixes it in."""
    import yaml

    from analysis.load import load_results
    from analysis.speed import speed_measurements
    from analysis_fixtures import write_run

    plain = write_run(tmp_path, experiment="speed", agent="taco", task="cheetah_run", seed=1, final=1.0, fps=10.0)
    fast = write_run(tmp_path, experiment="speed", agent="taco", task="cheetah_run", seed=2, final=1.0, fps=30.0)
    cfg = yaml.safe_load((fast / "config.yaml").read_text())
    cfg["agent"]["fast"] = True
    (fast / "config.yaml").write_text(yaml.safe_dump(cfg))
    results = load_results(tmp_path)
    by_seed = dict(zip(results.runs["seed"], results.runs["speedup"]))
    assert by_seed == {1: "plain", 2: "fast"} and plain.exists()
    meas = speed_measurements(results)
    assert sorted(zip(meas["fps"], meas["speedup"], meas["source"])) == [
        (10.0, "plain", "runs (speed)"), (30.0, "fast", "runs (speed) [fast]")]


def test_a_merge_replaces_the_entries_of_the_same_setting_and_keeps_the_others():
    """BenchFile.merge: an update entry of the same (agent, batch, path), an e2e entry of the same setting and timing,
    an offline entry of the same (agent, batch) replaced in its place; every other entry kept, the new ones after."""
    bench = br.parse({"device": "cpu", "results": [
        {"agent": "taco", "batch_size": 8, "path": "plain", "update_seconds": 2.0},
        {"agent": "taco", "batch_size": 8, "path": "fast", "update_seconds": 1.0}]})
    bench.merge(updates=[br.UpdateEntry("taco", 8, "fast", 0.5, load=3.5, cores=2),
                         br.UpdateEntry("alix", 8, "plain", 3.0, load=0.5, cores=2)])
    assert [(u.key, u.update_seconds) for u in bench.updates] == [
        (("taco", 8, "plain"), 2.0), (("taco", 8, "fast"), 0.5), (("alix", 8, "plain"), 3.0)]
    assert bench.under_load() == [bench.updates[1]] and not br.under_load(bench.updates[2])
    assert br.rate(bench, "taco", 8, "fast") == br.Rate(8.0, br.UPDATE_BOUND, None, 3.5, 2)  # the load comes along
    offline = br.parse({"device": "cpu", "kind": "offline", "results": [
        {"agent": "drqv2", "batch_size": 256, "update_seconds": 0.4}, {"agent": "cql", "batch_size": 256,
                                                                        "update_seconds": 0.8}]})
    offline.merge(offline=[br.OfflineEntry("cql", 256, 0.6), br.OfflineEntry("cql", 512, 1.2)])
    assert [(e.key, e.update_seconds) for e in offline.offline] == [
        (("drqv2", 256), 0.4), (("cql", 256), 0.6), (("cql", 512), 1.2)]
    again = br.parse(json.loads(json.dumps(bench.to_json())))
    assert again == bench and again.updates[1].load == 3.5 and again.updates[1].cores == 2
    assert br.loaded(2.01, 2) and not br.loaded(2.0, 2) and not br.loaded(None, 2)
