"""The run logs read without pandas (analysis/plaincsv.py): every column as pandas reads it, correctly rounded; any
other text left to pandas, with the same frames and the same problems from analysis.load.read_csv_strict."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import analysis.load
from analysis.load import EVAL_REQUIRED, TRAIN_REQUIRED, load_results, read_csv_strict
from analysis.plaincsv import NA_VALUES, plain_columns
from analysis_fixtures import write_run

# texts the runs write, and texts they do not (each left to pandas)
PLAIN = {
    "ints and floats": "frame,step,episode_reward\n0,0,0.0\n10000,5000,1.5\n20000,10000,-2e-05\n",
    "empty fields": "frame,success,critic_loss\n1000,,\n2000,1.0,\n3000,0.0,0.25\n",
    "every field empty": "frame,success\n1000,\n2000,\n",
    "mixed int and float": "frame,x\n1,2\n2,2.5\n3,1E3\n",
    "signs and bare points": "frame,x\n1,+5\n2,-0\n3,5.\n",
    "one column": "frame\n1\n2\n",
    "signed integers": "frame,x\n1,+5\n2,-0\n3,007\n",
    "largest integers": "frame,x\n1,999999999999999\n2,-99999999999999\n",
    "long float": "frame,x\n1,0.1000000000000000055511151231257827\n",
}
NOT_PLAIN = {
    "quoted": 'frame,x\n1,"2"\n',
    "blank line": "frame,x\n1,2\n\n3,4\n",
    "extra field": "frame,x\n1,2,3\n",
    "missing field": "frame,x\n1\n",
    "no final newline": "frame,x\n1,2",
    "no rows": "frame,x\n",
    "nan token": "frame,x\n1,nan\n",
    "text token": "frame,x\n1,abc\n",
    "broken exponent": "frame,x\n1,1e\n",
    "lone sign": "frame,x\n1,-\n",
    "lone point": "frame,x\n1,.\n",
    "lone plus": "frame,x\n1,+\n",
    "two signs": "frame,x\n1,--1\n",
    "two points": "frame,x\n1,1.2.3\n",
    "exponent without mantissa": "frame,x\n1,e5\n",
    "exponent without digits": "frame,x\n1,1e+\n",
    "sign inside": "frame,x\n1,1-2\n",
    "huge integer": "frame,x\n1,1234567890123456\n",
    "spaces": "frame,x\n1, 2\n",
    "carriage return": "frame,x\r\n1,2\r\n",
    "non-ascii": "frame,x\n1,2\u00b9\n",
    "duplicate names": "frame,frame\n1,2\n",
    "empty name": "frame,x,\n1,2,3\n",
    "byte order mark": "\ufeffframe,x\n1,2\n",
    "true": "frame,x\n1,True\n",
    "quote in a column not kept": 'frame,x\n1,"a,\n2"\n',
}


def _assert_reads_as_pandas(text: str, words: set[str] | None = None) -> None:
    """plain_columns gives pandas' header and every column with pandas' type and values (round trip), NaN for NaN."""
    header, columns = plain_columns(text, words=words or ())
    expected = pd.read_csv(io.StringIO(text), float_precision="round_trip")
    assert header == list(expected.columns) == list(columns)
    for col, values in columns.items():
        assert values.dtype == expected[col].dtype, col
        assert pd.Series(values).equals(expected[col]), col


@pytest.mark.parametrize("name", sorted(PLAIN))
def test_plain_text_reads_as_pandas_round_trip(name):
    _assert_reads_as_pandas(PLAIN[name])


# a text column (offline eval.csv's score_reference) of words, and of what pandas reads otherwise
WORDS = {
    "words": "update,ref\n0,paper\n1,d4rl_expert-v2\n",
    "words and empty fields": "update,ref\n0,paper\n1,\n",
    "every field empty": "update,ref\n0,\n1,\n",
}
NOT_WORDS = {
    "a number among words": "update,ref\n0,paper\n1,1.5\n",
    "missing-value spelling": "update,ref\n0,paper\n1,NA\n",
    "nan": "update,ref\n0,paper\n1,nan\n",
    "boolean": "update,ref\n0,True\n1,False\n",
    "infinity": "update,ref\n0,inf\n1,Infinity\n",
    "space": "update,ref\n0,a b\n",
}


@pytest.mark.parametrize("name", sorted(WORDS))
def test_words_read_as_pandas_reads_them(name):
    _assert_reads_as_pandas(WORDS[name], words={"ref"})


@pytest.mark.parametrize("name", sorted(NOT_WORDS))
def test_other_text_columns_are_left_to_pandas(name):
    assert plain_columns(NOT_WORDS[name], words={"ref"}) is None
    assert plain_columns(WORDS["words"]) is None  # words where numbers belong


def test_the_missing_value_spellings_are_those_pandas_reads_as_nan():
    """analysis.plaincsv.NA_VALUES (written out, not read from pandas' internals) is what read_csv reads as missing:
    on a sample of those spellings, their case variants and near misses, read_csv gives NaN exactly for the members
    (a pandas that adds, drops or re-cases a spelling fails here); and no member is kept as a word."""
    sample = set(NA_VALUES) | {"na", "Na", "NAN", "Nan", "NONE", "none", "Null", "N/a", "nul", "NA1", "#N/A N/a"}
    for value in list(NA_VALUES):
        sample |= {value.upper(), value.lower(), value.title(), value.swapcase()}
    sample.discard("")  # an empty field is NaN on both paths (WORDS' "words and empty fields")
    text = "update,ref\n0,paper\n" + "".join(f"{i + 1},{v}\n" for i, v in enumerate(sorted(sample)))
    read = pd.read_csv(io.StringIO(text))["ref"].iloc[1:]
    assert {v for v, r in zip(sorted(sample), read) if pd.isna(r)} == NA_VALUES - {""}
    for value in NA_VALUES - {""}:
        assert plain_columns(f"update,ref\n0,paper\n1,{value}\n", words={"ref"}) is None, value


@pytest.mark.parametrize("name", sorted(NOT_PLAIN))
def test_other_text_is_left_to_pandas(name):
    assert plain_columns(NOT_PLAIN[name]) is None


def test_keep_reads_only_the_columns_named():
    header, columns = plain_columns(PLAIN["ints and floats"], keep={"frame", "episode_reward"})
    assert header == ["frame", "step", "episode_reward"] and list(columns) == ["frame", "episode_reward"]


def test_numbers_come_back_exactly_as_written(tmp_path):
    """repr of a float read back is that float, on both paths (pandas' default parser is off in the last bit for
    about a quarter of these)."""
    values = np.random.default_rng(0).standard_normal(2000) * 1000
    path = tmp_path / "eval.csv"
    path.write_text("frame,step,episode,episode_reward\n" + "".join(
        f"{i},{i},{i},{v!r}\n" for i, v in enumerate(values.tolist())))
    assert (read_csv_strict(path, EVAL_REQUIRED)["episode_reward"].to_numpy() == values).all()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(analysis.load, "plain_columns", lambda *a, **k: None)
        assert (read_csv_strict(path, EVAL_REQUIRED)["episode_reward"].to_numpy() == values).all()


def _both_paths(path: Path, *args, **kwargs) -> tuple[object, object]:
    """read_csv_strict's frame (or its ValueError's message) on the plain path and with pandas only."""
    out = []
    for plain in (True, False):
        with pytest.MonkeyPatch.context() as mp:
            if not plain:
                mp.setattr(analysis.load, "plain_columns", lambda *a, **k: None)
            try:
                out.append(read_csv_strict(path, *args, **kwargs))
            except ValueError as exc:
                out.append(str(exc))
    return out[0], out[1]


CHECKED = {
    "good": "frame,step,episode,episode_reward,success\n0,0,0,0.0,\n10000,5000,1,1.5,\n",
    "empty required": "frame,step,episode,episode_reward\n0,0,0,0.0\n10000,5000,1,\n",
    "frames repeated": "frame,step,episode,episode_reward\n0,0,0,0.0\n0,5000,1,1.0\n",
    "frames reordered": "frame,step,episode,episode_reward\n10,0,0,0.0\n0,5000,1,1.0\n",
    "missing column": "frame,step,episode\n0,0,0\n",
    "extra field": "frame,step,episode,episode_reward\n0,0,0,0.0,9\n",
}


@pytest.mark.parametrize("name", sorted(CHECKED))
def test_read_csv_strict_is_the_same_on_both_paths(tmp_path, name):
    path = tmp_path / "eval.csv"
    path.write_text(CHECKED[name])
    plain, pandas_only = _both_paths(path, EVAL_REQUIRED)
    if isinstance(plain, str):
        assert plain == pandas_only
    else:
        pd.testing.assert_frame_equal(plain, pandas_only, check_exact=True)


def test_a_runs_logs_load_the_same_on_both_paths(tmp_path):
    """Runs as the fixture writes them (online with and without updates yet, Meta-world's success, offline):
    the runs and eval tables equal to the last bit with the plain reader and with pandas only."""
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=123.456789, fps=61.3)
    write_run(tmp_path, experiment="metaworld", agent="drqv2", task="hammer", seed=1, final=0.7, success=True)
    write_run(tmp_path, experiment="offline", agent="cql_taco", task="hopper_hop", seed=0, final=100.0,
              dataset="medium_replay", reference=250.0)
    train = next(tmp_path.rglob("train.csv"))
    plain_train, pandas_train = _both_paths(train, TRAIN_REQUIRED, only=("critic_loss",))
    pd.testing.assert_frame_equal(plain_train, pandas_train, check_exact=True)
    with_plain = load_results(tmp_path)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(analysis.load, "plain_columns", lambda *a, **k: None)
        pandas_only = load_results(tmp_path)
    pd.testing.assert_frame_equal(with_plain.runs, pandas_only.runs, check_exact=True)
    pd.testing.assert_frame_equal(with_plain.eval, pandas_only.eval, check_exact=True)
    assert with_plain.problems == pandas_only.problems


def _part(**cols) -> dict[str, np.ndarray]:
    return {k: np.asarray(v) for k, v in cols.items()}


CONCAT = {
    "integers and floats": [_part(a=np.array([1, 2])), _part(a=np.array([0.5]))],
    "words and empty fields": [_part(a=np.array(["paper", np.nan], dtype=object)), _part(a=np.full(2, np.nan))],
    "words and numbers": [_part(a=np.array(["paper"], dtype=object)), _part(a=np.array([1.5, 2.0]))],
    "booleans": [_part(a=np.array([True])), _part(a=np.array([False, True]))],
    "booleans and integers": [_part(a=np.array([True])), _part(a=np.array([3]))],
    "booleans and floats": [_part(a=np.array([False])), _part(a=np.array([np.nan]))],
}


@pytest.mark.parametrize("name", sorted(CONCAT))
def test_columns_join_as_pandas_concat_joins_frames(name):
    parts = CONCAT[name]
    expected = pd.concat([pd.DataFrame(p) for p in parts], ignore_index=True)
    pd.testing.assert_frame_equal(analysis.load._concat_columns(parts), expected, check_exact=True)


def test_integers_of_every_length_read_as_pandas_reads_them():
    """Integers of 1 to 15 characters, signed or not, with leading zeros: the digit-by-digit sum equals pandas."""
    rng = np.random.default_rng(3)
    digits = rng.integers(1, 15, size=3000)
    tokens = [rng.choice(["", "-", "+"]) + "".join(map(str, rng.integers(0, 10, size=d))) for d in digits]
    tokens = [t if len(t) <= 15 else t[:15] for t in tokens]
    text = "frame,x\n" + "".join(f"{i},{t}\n" for i, t in enumerate(tokens))
    _, columns = plain_columns(text)
    expected = pd.read_csv(io.StringIO(text))["x"]
    assert columns["x"].dtype == expected.dtype == np.int64
    np.testing.assert_array_equal(columns["x"], expected.to_numpy())
