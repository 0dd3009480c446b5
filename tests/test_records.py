"""Reading measured files into Records (``backlashkit.identify.readers.read_records``)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy import io as sio

from backlashkit.errors import InputError
from backlashkit.identify import Record
from backlashkit.identify.readers import read_records

TS = 1e-3
N = 50


def channels(n: int = N, ts: float = TS) -> dict[str, np.ndarray]:
    t = np.arange(n) * ts
    torque = np.where(np.arange(n) < n // 2, 0.5, 0.0)
    return {
        "t": t,
        "torque": torque,
        "w_motor": 1.0 + 0.25 * np.sin(40 * t),
        "w_load": 0.9 + 0.125 * np.cos(30 * t),
    }


def write_csv(path, cols, *, sep=",", dec=".", names=None, missing=()):
    names = names or {k: k for k in cols}
    keys = list(cols)
    lines = [sep.join(names[k] for k in keys)]
    n = len(cols[keys[0]])
    for i in range(n):
        cells = []
        for k in keys:
            text = "" if (k, i) in missing else repr(float(cols[k][i]))
            cells.append(text.replace(".", dec) if dec == "," else text)
        lines.append(sep.join(cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def assert_record(rec: Record, cols, *, speed_factor=1.0):
    assert isinstance(rec, Record)
    np.testing.assert_allclose(rec.t, cols["t"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rec.torque, cols["torque"])
    np.testing.assert_allclose(rec.w_motor, cols["w_motor"] * speed_factor, rtol=1e-15)
    np.testing.assert_allclose(rec.w_load, cols["w_load"] * speed_factor, rtol=1e-15)


def one_line(exc: pytest.ExceptionInfo, *fragments: str) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    for frag in fragments:
        assert frag in msg, msg
    return msg


# --- formats ------------------------------------------------------------------------


def test_csv_comma(tmp_path):
    cols = channels()
    path = write_csv(tmp_path / "exp.csv", cols)
    (rec,) = read_records(path)
    assert_record(rec, cols)
    assert rec.name == str(path)
    assert rec.ts == pytest.approx(TS)


def test_csv_semicolon_decimal_comma_autodetected(tmp_path):
    cols = channels()
    path = write_csv(tmp_path / "exp.csv", cols, sep=";", dec=",")
    assert "0,5" in path.read_text()
    (rec,) = read_records(path)
    assert_record(rec, cols)
    (rec2,) = read_records(path, delimiter=";", decimal=",")
    assert_record(rec2, cols)


def test_csv_tab_and_column_mapping(tmp_path):
    cols = channels()
    names = {"t": "time", "torque": "C_M", "w_motor": "omega_M", "w_load": "omega_L"}
    path = write_csv(tmp_path / "exp.tsv", cols, sep="\t", names=names)
    (rec,) = read_records(path, columns=names)
    assert_record(rec, cols)


def test_rpm_conversion(tmp_path):
    cols = channels()
    path = write_csv(tmp_path / "exp.csv", cols)
    (rec,) = read_records(path, speed_unit="rpm")
    assert_record(rec, cols, speed_factor=2 * math.pi / 60)


def test_sample_time_instead_of_time_column(tmp_path):
    cols = channels()
    no_t = {k: v for k, v in cols.items() if k != "t"}
    path = write_csv(tmp_path / "exp.csv", no_t)
    (rec,) = read_records(path, sample_time=TS)
    assert_record(rec, cols)
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "'t'", "columns=", "sample_time=")


def test_time_column_and_sample_time_conflict(tmp_path):
    path = write_csv(tmp_path / "exp.csv", channels())
    with pytest.raises(InputError) as exc:
        read_records(path, sample_time=TS)
    one_line(exc, str(path), "sample_time", "drop")
    with pytest.raises(InputError) as exc:
        read_records(path, sample_time=TS, columns={"t": "time"})
    one_line(exc, "sample_time", "not both")


def test_npz_single_and_suffixed(tmp_path):
    cols = channels()
    p1 = tmp_path / "one.npz"
    np.savez(p1, **cols)
    (rec,) = read_records(p1)
    assert_record(rec, cols)
    other = channels(60)
    p2 = tmp_path / "two.npz"
    np.savez(p2, **{f"{k}_1": v for k, v in cols.items()},
             **{f"{k}_2": v for k, v in other.items()})
    recs = read_records(p2)
    assert [r.name for r in recs] == [f"{p2}:_1", f"{p2}:_2"]
    assert_record(recs[0], cols)
    assert_record(recs[1], other)


def test_npz_shared_time_and_suffix_order(tmp_path):
    cols = channels()
    path = tmp_path / "shared.npz"
    payload = {"t": cols["t"]}
    for k in (10, 2):  # numerical, not lexical, order
        payload.update({f"torque_{k}": cols["torque"] * k, f"w_motor_{k}": cols["w_motor"],
                        f"w_load_{k}": cols["w_load"]})
    np.savez(path, **payload)
    recs = read_records(path)
    assert [r.name.rsplit(":", 1)[1] for r in recs] == ["_2", "_10"]
    np.testing.assert_array_equal(recs[1].torque, cols["torque"] * 10)


def test_mat_v5_variables_and_float32_time(tmp_path):
    cols = channels(2000)
    path = tmp_path / "exp.mat"
    # MATLAB stores column vectors; single-precision time snaps onto the uniform grid
    sio.savemat(path, {"t": cols["t"].astype(np.float32)[:, None], "torque": cols["torque"],
                       "w_motor": cols["w_motor"][:, None], "w_load": cols["w_load"]})
    (rec,) = read_records(path)
    np.testing.assert_allclose(rec.t, cols["t"], atol=1e-6)
    np.testing.assert_allclose(rec.w_motor, cols["w_motor"])


def test_mat_v5_struct_array(tmp_path):
    a, b = channels(), channels(70)
    arr = np.zeros((1, 2), dtype=[(k, object) for k in a])
    for j, c in enumerate((a, b)):
        for k in a:
            arr[0, j][k] = c[k][:, None]
    path = tmp_path / "runs.mat"
    sio.savemat(path, {"runs": arr})
    recs = read_records(path)
    assert [r.name for r in recs] == [f"{path}:runs(1)", f"{path}:runs(2)"]
    assert_record(recs[0], a)
    assert_record(recs[1], b)


def test_mat_v5_suffixed_with_mapping(tmp_path):
    a = channels()
    path = tmp_path / "exp.mat"
    sio.savemat(path, {"time_1": a["t"], "u_1": a["torque"], "wm_1": a["w_motor"],
                       "wl_1": a["w_load"]})
    recs = read_records(
        path, columns={"t": "time", "torque": "u", "w_motor": "wm", "w_load": "wl"}
    )
    assert len(recs) == 1 and recs[0].name == f"{path}:_1"
    assert_record(recs[0], a)


def test_mat_v73(tmp_path):
    import h5py  # a test dependency (.mat v7.3)
    a, b = channels(), channels(64)
    path = tmp_path / "v73.mat"
    with h5py.File(path, "w", userblock_size=512) as fh:
        for k, v in a.items():
            fh.create_dataset(k, data=v[None, :])  # MATLAB writes transposed
        g = fh.create_group("runs")
        refs = fh.create_group("#refs#")
        for k in a:
            ds = g.create_dataset(k, shape=(2, 1), dtype=h5py.ref_dtype)
            for j, c in enumerate((a, b)):
                target = refs.create_dataset(f"{k}{j}", data=c[k][None, :])
                ds[j, 0] = target.ref
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(116, b" "))
    (rec,) = read_records(path)  # plain variables win over the struct
    assert_record(rec, a)
    # only the struct: drop the plain variables
    with h5py.File(path, "a") as fh:
        for k in a:
            del fh[k]
    recs = read_records(path)
    assert [r.name for r in recs] == [f"{path}:runs(1)", f"{path}:runs(2)"]
    assert_record(recs[1], b)


def test_mat_v73_without_h5py(tmp_path, monkeypatch):
    import builtins

    path = tmp_path / "v73.mat"
    path.write_bytes(b"MATLAB 7.3 MAT-file".ljust(512, b" ") + b"\x89HDF\r\n\x1a\n" + b"\0" * 64)
    real = builtins.__import__

    def no_h5py(name, *args, **kwargs):
        if name == "h5py":
            raise ImportError("no h5py")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_h5py)
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "h5py", "-v7")


# --- resampling ------------------------------------------------------------------------


def test_resample_jitter_and_gap(tmp_path):
    cols = channels(201)
    t = cols["t"].copy()
    t[50] += 0.3 * TS  # jitter
    keep = np.ones(t.size, bool)
    keep[120:123] = False  # a gap of three samples
    w = 2.0 + 3.0 * t  # linear: interpolation is exact
    raw = {"t": t[keep], "torque": cols["torque"][keep], "w_motor": w[keep], "w_load": w[keep]}
    path = write_csv(tmp_path / "exp.csv", raw)
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "line 52", "resample='linear'")
    (rec,) = read_records(path, resample="linear")
    np.testing.assert_allclose(rec.t, np.arange(201) * TS, atol=1e-12)
    np.testing.assert_allclose(rec.w_motor, 2.0 + 3.0 * rec.t, rtol=1e-12)
    # torque is held (zero-order), so the step stays one sample wide
    np.testing.assert_array_equal(rec.torque, cols["torque"])


def test_gap_message(tmp_path):
    cols = channels()
    keep = np.ones(N, bool)
    keep[30:33] = False
    path = write_csv(tmp_path / "exp.csv", {k: v[keep] for k, v in cols.items()})
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "a gap", "line 31", "line 32", "resample='linear'")


def test_missing_values_bridged_only_on_request(tmp_path):
    cols = channels()
    cols["w_load"] = 1.0 + 2.0 * cols["t"]
    path = write_csv(tmp_path / "exp.csv", cols, missing={("w_load", 10), ("w_load", 11)})
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "line 12", "'w_load'", "missing", "resample='linear'")
    (rec,) = read_records(path, resample="linear")
    np.testing.assert_allclose(rec.w_load, cols["w_load"], rtol=1e-12)
    edge = write_csv(tmp_path / "edge.csv", cols, missing={("w_motor", 0)})
    with pytest.raises(InputError) as exc:
        read_records(edge, resample="linear")
    one_line(exc, str(edge), "line 2", "start", "crop")


def test_nan_in_npz(tmp_path):
    cols = channels()
    cols["w_motor"][7] = np.nan
    path = tmp_path / "nan.npz"
    np.savez(path, **cols)
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "sample 7", "'w_motor'", "resample='linear'")


def test_logical_npz_variable_is_refused(tmp_path):
    cols = channels()
    cols["torque"] = cols["torque"] > 0.5 * cols["torque"].max()  # a mask saved by mistake
    path = tmp_path / "mask.npz"
    np.savez(path, **cols)
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "variable 'torque' holds true/false values", "double(x)")


# --- malformed input --------------------------------------------------------------


@pytest.mark.parametrize(
    "text, fragments",
    [
        ("", ["empty", "header"]),
        ("1,2,3,4\n5,6,7,8\n", ["line 1", "holds numbers", "header"]),
        ("t,torque,w_motor\n0,1,2\n", ["no column 'w_load'", "columns="]),
        ("t,torque,w_motor,w_load\n0,1,2,3\n0.001,1,2\n0.002,1,2,3\n",
         ["line 3", "3 field(s)", "4"]),
        ("t,torque,w_motor,w_load\n0,1,2,3\n0.001,1,abc,3\n0.002,1,2,3\n",
         ["line 3", "'w_motor'", "'abc' is not a number"]),
        ("t,torque,w_motor,w_load\n0,1,2,3\n0.001,1,2,inf\n0.002,1,2,3\n",
         ["line 3", "infinite"]),
        ("t,torque,w_motor,w_load\n0,1,2,3\n0.002,1,2,3\n0.001,1,2,3\n",
         ["line 4", "does not increase", "sort"]),
        ("t,torque,w_motor,w_load\n0,1,2,3\n,1,2,3\n0.002,1,2,3\n",
         ["line 3", "time", "remove that row"]),
        ("t,torque,w_motor,w_load\n0,1,2,3\n0.001,1,2,3\n", ["too few samples"]),
        ("t,t,w_motor,w_load\n0,1,2,3\n", ["line 1", "appears twice"]),
        ("t;torque;w_motor;w_load\n0;1,5;2;3\n0,001;1;2;3\n0,002;1;2;3,5\n",
         []),  # valid: decimal comma detected
        # a thousands dot among decimal commas is refused, not read as a decimal point
        ("t;torque;w_motor;w_load\n0;1,5;3.819;3\n0,001;1;2;3\n0,002;1;2;3,5\n",
         ["line 2", "'3.819' has a '.' but the decimal mark is ','"]),
        ("t,torque,w_motor,w_load\n0,0_942,2,3\n0.001,1,2,3\n0.002,1,2,3\n",
         ["line 2", "'0_942' has an underscore"]),
        ("t,torque,w_motor,w_load\n", ["too few samples"]),  # header only: no numpy warning
        ("t,torque,w_motor,w_load\n2024-01-01 00:00:00.000,1,2,3\n",
         ["line 2", "a date or clock time is no time in s", "sample_time="]),
    ],
)
def test_malformed_csv(tmp_path, text, fragments):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    if not fragments:
        (rec,) = read_records(path)
        assert rec.torque[0] == 1.5 and rec.w_load[-1] == 3.5
        return
    with pytest.raises(InputError) as exc, warnings.catch_warnings():
        warnings.simplefilter("error")  # the message is the only output
        read_records(path)
    one_line(exc, str(path), *fragments)


def test_decimal_comma_with_comma_separator_is_a_hint(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text('t,torque,w_motor,w_load\n0,1,2,3\n0.001,"1,5",2,3\n0.002,1,2,3\n')
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "line 3", "decimal=','")


def test_not_utf8(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_bytes(b"t,torque,w_motor,w_load\n\xff\xfe,1,2,3\n")
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, str(path), "UTF-8")


def test_utf16_with_a_byte_order_mark(tmp_path):
    """Excel's "Unicode text" export: UTF-16 with a BOM, tab-separated."""
    cols = channels()
    path = write_csv(tmp_path / "excel.txt", cols, sep="\t")
    path.write_text(path.read_text(encoding="utf-8"), encoding="utf-16")
    assert path.read_bytes()[:2] in (b"\xff\xfe", b"\xfe\xff")
    (rec,) = read_records(path)
    assert_record(rec, cols)


def test_malformed_binary_files(tmp_path):
    bad_mat = tmp_path / "bad.mat"
    bad_mat.write_bytes(b"this is not a mat file at all" * 10)
    with pytest.raises(InputError) as exc:
        read_records(bad_mat)
    one_line(exc, str(bad_mat), "MATLAB")
    bad_npz = tmp_path / "bad.npz"
    bad_npz.write_bytes(b"nope")
    with pytest.raises(InputError) as exc:
        read_records(bad_npz)
    one_line(exc, str(bad_npz), ".npz")
    cols = channels()
    missing = tmp_path / "missing.npz"
    np.savez(missing, t=cols["t"], torque=cols["torque"], w_motor=cols["w_motor"])
    with pytest.raises(InputError) as exc:
        read_records(missing)
    one_line(exc, str(missing), "'w_load'", "columns=")
    matrix = tmp_path / "matrix.npz"
    np.savez(matrix, t=cols["t"], torque=cols["torque"], w_motor=np.ones((N, 2)),
             w_load=cols["w_load"])
    with pytest.raises(InputError) as exc:
        read_records(matrix)
    one_line(exc, str(matrix), "'w_motor'", "vector", "(50, 2)")
    lengths = tmp_path / "lengths.npz"
    np.savez(lengths, t=cols["t"], torque=cols["torque"], w_motor=cols["w_motor"][:-1],
             w_load=cols["w_load"])
    with pytest.raises(InputError) as exc:
        read_records(lengths)
    one_line(exc, str(lengths), "different lengths", "w_motor: 49")
    incomplete = tmp_path / "incomplete.npz"
    np.savez(incomplete, **{f"{k}_1": v for k, v in cols.items()},
             **{f"{k}_2": v for k, v in cols.items() if k != "w_load"})
    with pytest.raises(InputError) as exc:
        read_records(incomplete)
    one_line(exc, str(incomplete), "_2", "'w_load_2'")


@pytest.mark.parametrize(
    "kwargs, fragments",
    [
        ({"columns": {"speed": "x"}}, ["columns", "'speed'", "allowed keys"]),
        ({"columns": {"t": ""}}, ["columns['t']", "non-empty"]),
        ({"sample_time": 0.0}, ["sample_time", "> 0", "0.0"]),
        ({"sample_time": "fast"}, ["sample_time", "'fast'"]),
        ({"delimiter": "|"}, ["delimiter", "'|'"]),
        ({"decimal": ";"}, ["decimal", "';'"]),
        ({"decimal": ",", "delimiter": ","}, ["decimal ','", "delimiter"]),
        ({"speed_unit": "rev/s"}, ["speed_unit", "'rpm'", "'deg/s'", "'rev/s'"]),
        ({"resample": "cubic"}, ["resample", "'linear'", "'cubic'"]),
    ],
)
def test_invalid_options(tmp_path, kwargs, fragments):
    path = write_csv(tmp_path / "exp.csv", channels())
    with pytest.raises(InputError) as exc:
        read_records(path, **kwargs)
    one_line(exc, *fragments)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_records(tmp_path / "nope.csv")
    with pytest.raises(InputError) as exc:
        read_records(tmp_path)
    one_line(exc, "directory")


@pytest.mark.parametrize(
    "text",
    [
        "t,torque,w_motor,w_load\n0,1,2,3\n0.001,1,2.5,nan\n0.002,0,2e-1,3.5\n",
        "# comment\n\nt;torque;w_motor;w_load\n0;1;2,5;3\n# mid\n0,001;1;2;3\n\n0,002;0;1;1\n",
        "t\ttorque\tw_motor\tw_load\r\n0\t1\t2\t3\r\n0.001\t1\t2\t3\r\n0.002\t0\t1\t1\r\n",
        " t , torque , w_motor , w_load \n 0 , 1 , 2 , 3 \n0.001,1,2,3\n0.002,0,1,1\n",
    ],
)
def test_csv_fast_path_matches_line_reader(tmp_path, monkeypatch, text):
    """The numpy.loadtxt path and the line-by-line reader read a file identically."""
    import backlashkit.identify._csv_reader as records

    path = tmp_path / "x.csv"
    path.write_text(text, encoding="utf-8")
    kw = {"resample": "linear"} if "nan" in text else {}
    fast = read_records(path, **kw)[0]
    monkeypatch.setattr(records, "_fast_csv", lambda *a: None)
    slow = read_records(path, **kw)[0]
    for ch in ("t", "torque", "w_motor", "w_load"):
        np.testing.assert_array_equal(getattr(fast, ch), getattr(slow, ch))


def test_csv_fast_path_keeps_line_numbers(tmp_path):
    """Errors found after parsing (here a time step) still name the file's line."""
    path = tmp_path / "x.csv"
    path.write_text("# c\nt,torque,w_motor,w_load\n0,1,2,3\n\n0.001,1,2,3\n0.005,0,1,1\n")
    with pytest.raises(InputError) as exc:
        read_records(path)
    one_line(exc, "x.csv", "between line 3 and line 5")  # the blank line 4 counted


def test_resampling_bridges_short_gaps_only(tmp_path):
    """``resample="linear"`` bridges up to MAX_BRIDGE missing samples in a row; a longer
    gap (or run of NaN) would hide an impact: an error naming it."""
    from backlashkit.identify.readers import MAX_BRIDGE

    cols = channels(200)
    for gap in (MAX_BRIDGE, MAX_BRIDGE + 1):
        keep = np.ones(200, bool)
        keep[50 : 50 + gap] = False
        path = write_csv(tmp_path / f"gap{gap}.csv", {k: v[keep] for k, v in cols.items()})
        if gap <= MAX_BRIDGE:
            (rec,) = read_records(path, resample="linear")
            np.testing.assert_allclose(rec.t, cols["t"], atol=1e-12)
        else:
            with pytest.raises(InputError) as exc:
                read_records(path, resample="linear")
            one_line(exc, f"{MAX_BRIDGE + 1} missing samples", "crop the record")
        missing = {("w_load", i) for i in range(50, 50 + gap)}
        path = write_csv(tmp_path / f"nan{gap}.csv", cols, missing=missing)
        if gap <= MAX_BRIDGE:
            (rec,) = read_records(path, resample="linear")
            assert np.isfinite(rec.w_load).all()
        else:
            with pytest.raises(InputError) as exc:
                read_records(path, resample="linear")
            one_line(exc, "line 52", "'w_load' is missing for 11 samples in a row")


def test_wrong_delimiter_is_named(tmp_path):
    path = tmp_path / "tab.csv"
    path.write_text("t\ttorque\tw_motor\tw_load\n0\t1\t2\t3\n0.001\t1\t2\t3\n")
    with pytest.raises(InputError) as exc:
        read_records(path, delimiter=";")
    one_line(exc, "separated by tab, not ';'", "pass delimiter='\\t'")


def test_mat_structs_missing_a_field_and_complex_v73(tmp_path):
    import h5py  # a test dependency (.mat v7.3)
    t = np.arange(10) * 1e-3
    sio.savemat(tmp_path / "s5.mat", {"exp": {"t": t, "torque": t, "w_motor": t}})
    with pytest.raises(InputError) as exc:
        read_records(tmp_path / "s5.mat")
    one_line(exc, "struct 'exp' has no field 'w_load' (it has 't', 'torque', 'w_motor')")
    with h5py.File(tmp_path / "g73.mat", "w") as fh:  # the same struct in HDF5 (v7.3)
        group = fh.create_group("exp")
        for key in ("t", "torque", "w_motor"):
            group[key] = t
    with pytest.raises(InputError) as exc:
        read_records(tmp_path / "g73.mat")
    one_line(exc, "struct 'exp' has no field 'w_load'")
    dtype = np.dtype([("real", float), ("imag", float)])  # how MATLAB stores complex
    with h5py.File(tmp_path / "c73.mat", "w") as fh:
        for key in ("t", "torque", "w_load"):
            fh[key] = t
        fh["w_motor"] = np.zeros(10, dtype)
    with pytest.raises(InputError) as exc:
        read_records(tmp_path / "c73.mat")
    one_line(exc, "variable 'w_motor' holds complex numbers, not real numbers")


def test_mat_v5_cells_and_sparse_are_named(tmp_path):
    import scipy.sparse

    t = np.arange(10) * 1e-3
    cell = np.empty((1, 2), dtype=object)
    cell[0, 0], cell[0, 1] = t, t
    sio.savemat(tmp_path / "cell.mat", {"t": t, "torque": t, "w_motor": cell, "w_load": t})
    with pytest.raises(InputError) as exc:
        read_records(tmp_path / "cell.mat")
    one_line(exc, "variable 'w_motor' holds a cell array or other objects, not numbers")
    sparse = scipy.sparse.csc_matrix(t.reshape(-1, 1))
    sio.savemat(tmp_path / "sp.mat", {"t": t, "torque": t, "w_motor": sparse, "w_load": t})
    with pytest.raises(InputError) as exc:
        read_records(tmp_path / "sp.mat")
    one_line(exc, "variable 'w_motor' is a sparse matrix", "full(x) in MATLAB")


def test_npz_with_plain_and_numbered_channels_is_refused(tmp_path):
    cols = channels()
    np.savez(tmp_path / "both.npz", **cols, w_motor_1=cols["w_motor"], w_load_1=cols["w_load"],
             torque_1=cols["torque"])
    with pytest.raises(InputError) as exc:
        read_records(tmp_path / "both.npz")
    one_line(exc, "holds both plain arrays", "'w_motor_1'", "keep one naming scheme")


# --- torque files (the cases of the former second reader, backlashkit.io) ----------

BAD_TORQUE_CSV = {
    "missing column": ("t,tau\n0,1\n0.1,1\n0.2,1\n", r"no column 'torque' in the header"),
    "missing t": ("time,torque\n0,1\n0.1,1\n0.2,1\n", r"no column 't' in the header"),
    "no separator": ("t torque\n0 1\n0.1 1\n", r"no column 't', 'torque'.*\['t torque'\]"),
    "empty": ("", "the file is empty"),
    "header only": ("t,torque\n", r"too few samples \(0\)"),
    "one sample": ("t,torque\n0,1\n", r"too few samples \(1\)"),
    "non numeric": ("t,torque\n0,1\n0.1,abc\n0.2,1\n", r"line 3, column 'torque': 'abc' is not a"),
    "nan": ("t,torque\n0,1\n0.1,nan\n0.2,1\n", r"line 3: 'torque' is missing"),
    "inf": ("t,torque\n0,1\n0.1,1\n0.2,-inf\n", r"line 4, column 'torque': '-inf' is infinite"),
    "non monotonic": ("t,torque\n0,1\n0.2,1\n0.1,1\n", r"line 4: the time 't' = 0\.1 does not "
                      "increase"),
    "non uniform": ("t,torque\n0,1\n0.1,1\n0.25,1\n0.3,1\n", r"non-uniform step .* line 3"),
    "ragged row": ("t,torque\n0,1\n0.1,1,5\n", r"line 3 has 3 field\(s\) but the header has 2"),
    "duplicate column": ("t,torque,t\n0,1,0\n0.1,1,0.1\n", "column 't' appears twice"),
}


@pytest.mark.parametrize("case", list(BAD_TORQUE_CSV), ids=list(BAD_TORQUE_CSV))
def test_bad_torque_file(tmp_path, case):
    from backlashkit.identify.readers import read_torque

    text, culprit = BAD_TORQUE_CSV[case]
    path = tmp_path / "torque.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=culprit) as info:
        read_torque(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and "\n" not in msg


def test_torque_file_by_name_with_extras_and_separators(tmp_path):
    from backlashkit.identify.readers import read_torque

    path = tmp_path / "torque.csv"
    path.write_text("\ufeff# a comment\nw_motor, torque ,t\n1,0.5,0.0\n\n2,0.25,0.001\n"
                    "3,-1e-3,0.002\n", encoding="utf-8")
    t, u = read_torque(path)
    np.testing.assert_array_equal(t, [0.0, 0.001, 0.002])
    np.testing.assert_array_equal(u, [0.5, 0.25, -1e-3])
    for sep in (";", "\t"):
        path.write_text(f"t{sep}torque\n0{sep}1\n0.1{sep}0.5\n0.2{sep}0.5\n")
        t, u = read_torque(path)
        np.testing.assert_allclose(t, [0.0, 0.1, 0.2])
        np.testing.assert_array_equal(u, [1.0, 0.5, 0.5])
    path.write_bytes(b"t,torque\n0,\xff\n")
    with pytest.raises(InputError, match="not a UTF-8"):
        read_torque(path)

