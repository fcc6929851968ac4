"""Loader features with data written by the tests (numpy, pandas, scipy.io): .mat orientation, headerless
tables, CSV header rules, bounds, separate estimation/validation records (segments), the split they
imply and prefilters that respect segment boundaries."""

import hashlib

import numpy as np
import pandas as pd
import pytest
import scipy.io
import yaml

from pipeline.config import load_config
from pipeline.data import Segment, apply_prefilters, load_record, make_split
from pipeline.errors import ConfigError, DataError
from pipeline.prefilter import lowpass_zero_phase

MODEL = {"states": ["y"], "inputs": ["u"], "params": {"a": 1.0, "b": 1.0}, "equations": {"y": "-a*y + b*u"}}


def _signals(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n), rng.standard_normal(n)


def _load(tmp_path, data, **extra):
    cfg = {"name": "t", "data": data, "model": MODEL, **extra}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    lc = load_config(tmp_path / "c.yaml")
    return lc, load_record(lc)


# --------------------------------------------------------------------------------------------- .mat
@pytest.mark.parametrize("transpose", [False, True])
def test_mat_channels_run_along_the_longer_dimension(tmp_path, transpose):
    """A 3 x 2000 matrix and its transpose both give 3 channels of 2000 samples (sig_1..sig_3)."""
    u, y = _signals(2000)
    t = np.arange(2000) * 0.05
    m = np.vstack([t, u, y])                      # channels x samples
    scipy.io.savemat(tmp_path / "d.mat", {"sig": m.T if transpose else m})
    _, rec = _load(tmp_path, {"path": "d.mat", "time": "sig_1", "inputs": {"sig_2": "u"}, "outputs": {"sig_3": "y"}})
    assert rec.n == 2000 and rec.dt == pytest.approx(0.05)
    np.testing.assert_array_equal(rec.inputs["u"], u)
    np.testing.assert_array_equal(rec.outputs["y"], y)


def test_mat_vectors_of_different_lengths_are_refused_naming_both(tmp_path):
    u, y = _signals(1000)
    scipy.io.savemat(tmp_path / "d.mat", {"u": u[None, :], "y": y[:990, None]})
    with pytest.raises(DataError) as e:
        _load(tmp_path, {"path": "d.mat", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]})
    assert "'y' (output) has 990 samples" in str(e.value) and "'u' (input) has 1000" in str(e.value)
    assert str(tmp_path / "d.mat") in str(e.value)


def test_mat_declared_size_is_bounded_before_loading(tmp_path):
    u = y = np.tile([1.0, -1.0], 1500)            # compresses to far less than its 23.4 KiB
    scipy.io.savemat(tmp_path / "d.mat", {"u": u, "y": y}, do_compression=True)
    assert (tmp_path / "d.mat").stat().st_size < 20000
    with pytest.raises(DataError, match="'u' holds 3000 samples, more than data.max_samples = 2999"):
        _load(tmp_path, {"path": "d.mat", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"], "max_samples": 2999})
    with pytest.raises(DataError, match="decodes to 23.4 KiB, more than data.max_bytes"):
        _load(tmp_path, {"path": "d.mat", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"], "max_bytes": 20000})


# -------------------------------------------------------------------------------------------- table
def _write_table(path, rows, sep="  ", decimal=".", eol="\r\n", head="", trailing=""):
    text = head
    for r in rows:
        text += sep.join(f"{v:.6f}".replace(".", decimal) for v in r) + trailing + eol
    path.write_bytes(text.encode())


@pytest.mark.parametrize("variant", ["whitespace_crlf", "tab_trailing", "semicolon_comma", "comments_skip"])
def test_table_reads_headerless_text(tmp_path, variant):
    u, y = _signals(300)
    t = np.arange(300) * 2.0
    rows = np.column_stack([t, u, y])
    expect = np.array([[float(f"{v:.6f}") for v in r] for r in rows])
    data = {"path": "d.dat", "format": "table", "columns": ["t", "u", "y"], "time": "t", "inputs": ["u"],
            "outputs": ["y"]}
    if variant == "whitespace_crlf":
        _write_table(tmp_path / "d.dat", rows)
    elif variant == "tab_trailing":                       # DaISy: tab-separated with a tab at line end
        _write_table(tmp_path / "d.dat", rows, sep="\t", trailing="\t")
        data["delimiter"] = "\t"
    elif variant == "semicolon_comma":
        _write_table(tmp_path / "d.dat", rows, sep=";", decimal=",", eol="\n")
        data.update(delimiter=";", decimal=",")
    else:
        _write_table(tmp_path / "d.dat", rows, head="Heating system, DaISy 99-001\nsecond title line\n"
                     "# t u y\n\n")
        data["skip_rows"] = 2
    _, rec = _load(tmp_path, data)
    assert rec.n == 300 and rec.dt == pytest.approx(2.0)
    np.testing.assert_array_equal(rec.t, expect[:, 0])
    np.testing.assert_array_equal(rec.inputs["u"], expect[:, 1])
    np.testing.assert_array_equal(rec.outputs["y"], expect[:, 2])


def test_table_counts_columns_and_refuses_a_longer_line(tmp_path):
    u, y = _signals(100)
    _write_table(tmp_path / "d.dat", np.column_stack([u, y]))
    base = {"path": "d.dat", "format": "table", "sample_time": 1.0, "inputs": ["u"], "outputs": ["y"]}
    with pytest.raises(DataError, match=r"data.columns names 3 columns .* holds 2 fields"):
        _load(tmp_path, {**base, "columns": ["u", "y", "z"]})
    text = (tmp_path / "d.dat").read_text().splitlines()
    text[40] += "  7.0"
    (tmp_path / "d.dat").write_text("\n".join(text) + "\n")
    with pytest.raises(DataError, match="line 41"):
        _load(tmp_path, {**base, "columns": ["u", "y"]})


# ---------------------------------------------------------------------------------------------- csv
def test_csv_duplicate_header_name_is_refused_only_when_used(tmp_path):
    u, y = _signals(200)
    (tmp_path / "d.csv").write_text("u,y,z,z\n" + "".join(f"{a},{b},1,2\n" for a, b in zip(u, y)))
    _, rec = _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]})
    np.testing.assert_array_equal(rec.outputs["y"], y)
    with pytest.raises(DataError, match=r"column 'z' appears 2 times in the header \(columns 3 and 4\)"):
        _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": {"z": "y"}})


def test_csv_reads_only_the_needed_columns(tmp_path):
    """An unused column of text (a comment field, a date) does not stop the load."""
    u, y = _signals(200)
    pd.DataFrame({"when": ["2024-01-01 10:00"] * 200, "u": u, "note": ["ok"] * 200, "y": y}).to_csv(
        tmp_path / "d.csv", index=False)
    _, rec = _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]})
    np.testing.assert_array_equal(rec.inputs["u"], u)


def test_csv_decimal_comma_and_true_false_column(tmp_path):
    u, y = _signals(100)
    lines = ["u;y;valve"] + [f"{a:.5f};{b:.5f};{'True' if k % 3 else 'False'}".replace(".", ",")
                             for k, (a, b) in enumerate(zip(u, y))]
    (tmp_path / "d.csv").write_text("\n".join(lines) + "\n")
    _, rec = _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": {"valve": "u"}, "outputs": ["y"],
                              "delimiter": ";", "decimal": ","})
    np.testing.assert_array_equal(rec.inputs["u"], [0.0 if k % 3 == 0 else 1.0 for k in range(100)])
    np.testing.assert_array_equal(rec.outputs["y"], [float(f"{b:.5f}") for b in y])


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_row_bound_is_exact(tmp_path, fmt):
    u, y = _signals(1000)
    df = pd.DataFrame({"u": u, "y": y})
    name = f"d.{fmt}"
    df.to_csv(tmp_path / name, index=False) if fmt == "csv" else df.to_parquet(tmp_path / name)
    data = {"path": name, "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]}
    assert _load(tmp_path, {**data, "max_samples": 1000})[1].n == 1000
    with pytest.raises(DataError, match="more than data.max_samples = 999 rows"):
        _load(tmp_path, {**data, "max_samples": 999})


def test_file_size_bound_uses_stat(tmp_path):
    u, y = _signals(100)
    pd.DataFrame({"u": u, "y": y}).to_csv(tmp_path / "d.csv", index=False)
    size = (tmp_path / "d.csv").stat().st_size
    data = {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]}
    assert _load(tmp_path, {**data, "max_bytes": size})[1].n == 100
    with pytest.raises(DataError, match=f"holds {size / 1024:.3g} KiB, more than data.max_bytes"):
        _load(tmp_path, {**data, "max_bytes": size - 1})


def test_plain_record_is_one_segment_with_its_file_hash(tmp_path):
    u, y = _signals(100)
    pd.DataFrame({"u": u, "y": y}).to_csv(tmp_path / "d.csv", index=False)
    _, rec = _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]})
    assert rec.segments == [Segment("record", 0, 100, None)] and not rec.has_roles
    assert rec.sha256 == hashlib.sha256((tmp_path / "d.csv").read_bytes()).hexdigest()


# ------------------------------------------------------------------------------ separate records
def _two_files(tmp_path, n_est=400, n_val=300):
    ue, ye = _signals(n_est, 1)
    uv, yv = _signals(n_val, 2)
    pd.DataFrame({"t": np.arange(n_est) * 0.1, "u": ue, "y": ye}).to_csv(tmp_path / "est.csv", index=False)
    pd.DataFrame({"u": uv, "y": yv}).to_csv(tmp_path / "val.csv", index=False)
    return ue, ye, uv, yv


def test_validation_record_in_its_own_file(tmp_path):
    ue, ye, uv, yv = _two_files(tmp_path)
    lc, rec = _load(tmp_path, {"path": "est.csv", "time": "t", "inputs": ["u"], "outputs": ["y"],
                               "validation": {"path": "val.csv", "sample_time": 0.1}})
    assert rec.segments == [Segment("estimation", 0, 400, "estimation"), Segment("validation", 400, 700, "validation")]
    np.testing.assert_array_equal(rec.outputs["y"], np.concatenate([ye, yv]))
    np.testing.assert_allclose(rec.t[400:], np.arange(300) * 0.1)       # each segment's own time
    assert rec.t[0] == 0 and rec.t[400] == 0
    split = make_split(lc, rec)
    assert (split.est, split.val) == ((0, 400), (400, 700))
    # the fingerprint covers both files: it changes when only the validation file changes
    sha1 = rec.sha256
    assert sha1 not in (hashlib.sha256((tmp_path / f).read_bytes()).hexdigest() for f in ("est.csv", "val.csv"))
    assert _load(tmp_path, yaml.safe_load((tmp_path / "c.yaml").read_text())["data"])[1].sha256 == sha1
    pd.DataFrame({"u": uv, "y": yv + 1e-9}).to_csv(tmp_path / "val.csv", index=False)
    assert _load(tmp_path, yaml.safe_load((tmp_path / "c.yaml").read_text())["data"])[1].sha256 != sha1


def test_experiments_side_by_side_in_one_file_estimation_first(tmp_path):
    """Path defaults to data.path; the record puts estimation experiments first whatever the list order."""
    ue, ye = _signals(500, 1)
    uv, yv = _signals(500, 2)
    pd.DataFrame({"uEst": ue, "uVal": uv, "yEst": ye, "yVal": yv}).to_csv(tmp_path / "d.csv", index=False)
    lc, rec = _load(tmp_path, {"path": "d.csv", "sample_time": 4, "inputs": {"uEst": "u"}, "outputs": {"yEst": "y"},
                               "experiments": [{"inputs": {"uVal": "u"}, "outputs": {"yVal": "y"}, "role": "validation"},
                                               {"role": "estimation", "name": "multisine"}]})
    assert [(g.name, g.role, g.start, g.stop) for g in rec.segments] == \
        [("multisine", "estimation", 0, 500), ("experiment 1", "validation", 500, 1000)]
    np.testing.assert_array_equal(rec.inputs["u"], np.concatenate([ue, uv]))
    assert make_split(lc, rec).val == (500, 1000)


@pytest.mark.parametrize("data_extra,key", [
    ({"validation": {"path": "val.csv", "sample_time": 0.2}}, "data.validation"),
    ({"validation": {"path": "val.csv", "sample_time": 0.1, "outputs": {"u": "y"}, "inputs": {"y": "u"}}}, None),
])
def test_validation_record_must_match_sampling(tmp_path, data_extra, key):
    _two_files(tmp_path)
    data = {"path": "est.csv", "time": "t", "inputs": ["u"], "outputs": ["y"], **data_extra}
    if key is None:       # swapped columns are fine: the same model names are measured
        assert _load(tmp_path, data)[1].n == 700
        return
    with pytest.raises(DataError, match="sampled every 0.2 s") as e:
        _load(tmp_path, data)
    assert f"{tmp_path / 'val.csv'}: {key}:" in str(e.value)


def test_roles_and_split_ranges_together_are_refused(tmp_path):
    _two_files(tmp_path)
    data = {"path": "est.csv", "time": "t", "inputs": ["u"], "outputs": ["y"],
            "validation": {"path": "val.csv", "sample_time": 0.1}}
    for split in ({"estimation": [0, 200], "validation": [200, None]}, {"validation_fraction": 0.5}):
        lc, rec = _load(tmp_path, data, split=split)
        with pytest.raises(ConfigError) as e:
            make_split(lc, rec)
        assert e.value.key == "split" and "cannot be combined" in str(e.value)


# -------------------------------------------------------------------------------------- prefilters
def _segmented(tmp_path):
    _two_files(tmp_path)
    return _load(tmp_path, {"path": "est.csv", "time": "t", "inputs": ["u"], "outputs": ["y"],
                            "validation": {"path": "val.csv", "sample_time": 0.1}})


def test_prefilters_run_per_segment(tmp_path):
    """A zero-phase low-pass on the concatenation would carry the estimation record into the validation
    one; per segment, each part equals the filter applied to that record alone."""
    lc, rec = _segmented(tmp_path)
    y = rec.outputs["y"].copy()
    step = yaml.safe_load("{name: lowpass, params: {cutoff: 1.0, order: 4}}")
    from pipeline.config import PrefilterStepCfg
    apply_prefilters(rec, [PrefilterStepCfg(**step)], "c.yaml")
    np.testing.assert_allclose(rec.outputs["y"][400:], lowpass_zero_phase(y[400:], 10.0, 1.0, 4), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.outputs["y"][:400], lowpass_zero_phase(y[:400], 10.0, 1.0, 4), rtol=0, atol=1e-12)
    assert np.max(np.abs(rec.outputs["y"][400:410] - lowpass_zero_phase(y, 10.0, 1.0, 4)[400:410])) > 1e-3


def test_decimate_updates_segments_and_rechecks_min_samples(tmp_path):
    from pipeline.config import PrefilterStepCfg
    lc, rec = _segmented(tmp_path)
    apply_prefilters(rec, [PrefilterStepCfg(name="decimate", params={"q": 3})], "c.yaml", min_samples=50)
    # ceil(400/3) = 134, ceil(300/3) = 100
    assert [(g.start, g.stop) for g in rec.segments] == [(0, 134), (134, 234)]
    assert rec.n == 234 and rec.dt == pytest.approx(0.3)
    np.testing.assert_allclose(rec.t[134:136], [0.0, 0.3])
    lc, rec = _segmented(tmp_path)
    with pytest.raises(DataError, match="after decimation by 4, segment 'validation' holds 75 samples; at least 80") as e:
        apply_prefilters(rec, [PrefilterStepCfg(name="decimate", params={"q": 4})], "c.yaml", min_samples=80)
    assert e.value.key == "prefilter[0]"


def test_state_variable_filter_output_index_is_checked(tmp_path):
    from pipeline.config import PrefilterStepCfg
    lc, rec = _segmented(tmp_path)
    for out in (3, -1, True):
        step = PrefilterStepCfg(name="state_variable_filter", params={"order": 2, "omega_c": 5.0, "output": out})
        with pytest.raises(DataError, match=r"output index .* out of range.* outputs 0..2") as e:
            apply_prefilters(rec, [step], "c.yaml")
        assert e.value.key == "prefilter[0].params.output"
    step = PrefilterStepCfg(name="state_variable_filter", params={"order": 2, "omega_c": 5.0, "output": 2})
    apply_prefilters(rec, [step], "c.yaml")
    assert rec.n == 700


def test_text_without_line_breaks_is_refused_after_one_mebibyte(tmp_path):
    from pipeline.loaders.text import MAX_LINE
    (tmp_path / "d.csv").write_text("u,y" + ",1" * (MAX_LINE // 2))
    with pytest.raises(DataError, match="line 1 is longer than 1048576 characters"):
        _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"]})


def test_default_row_bound_is_one_the_diagnosis_can_hold_in_memory(tmp_path):
    """An independent probe ran a 2 000 000-row record to 4.9 GB peak memory and 7.5 min; the old default
    (50 000 000 rows) would have let a file 25 times longer run out of memory. The default is 1 000 000
    rows, the same in the config and the loaders, and the message says what a row costs and what to do."""
    from pipeline.config import DataCfg
    from pipeline.loaders.spec import DEFAULT_MAX_SAMPLES
    assert DataCfg.model_fields["max_samples"].default == DEFAULT_MAX_SAMPLES == 1_000_000
    (tmp_path / "d.csv").write_text("u,y\n" + "1.0,2.0\n" * 31)
    with pytest.raises(DataError) as e:
        _load(tmp_path, {"path": "d.csv", "sample_time": 0.1, "inputs": ["u"], "outputs": ["y"], "max_samples": 30})
    assert "more than data.max_samples = 30 rows" in str(e.value) and "decimate" in str(e.value)


def test_a_file_with_another_delimiter_says_which_to_set(tmp_path):
    """A semicolon file read with the default "," gave "column 'u' (input) not found; columns: 't;u;x'"
    (an independent probe); the message now names the delimiter to set."""
    (tmp_path / "d.csv").write_text("t;u;y\n" + "".join(f"{0.1 * i};{i % 3};{i % 5}\n" for i in range(60)))
    with pytest.raises(DataError) as e:
        _load(tmp_path, {"path": "d.csv", "time": "t", "inputs": ["u"], "outputs": ["y"]})
    assert "set data.delimiter: ';'" in str(e.value)
    _load(tmp_path, {"path": "d.csv", "time": "t", "inputs": ["u"], "outputs": ["y"], "delimiter": ";"})
