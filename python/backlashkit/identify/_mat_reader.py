"""MATLAB ``.mat`` (v4-v7 through scipy, v7.3 through h5py) and NumPy ``.npz`` files to
raw channels, for :mod:`backlashkit.identify.readers`."""

from __future__ import annotations

import re
import zipfile
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..errors import InputError
from ._csv_reader import PASS_SAMPLE_TIME, _precision, _Raw, map_columns

_SUFFIX = re.compile(r"^(.*)_(\d+)$")

def _vector(name: str, var: str, value: Any) -> np.ndarray:
    if hasattr(value, "toarray"):  # a scipy.sparse matrix (MATLAB's sparse)
        raise InputError(f"{name}: variable {var!r} is a sparse matrix; save it as a full "
                         "numeric vector (full(x) in MATLAB)")
    arr = np.asarray(value)
    if arr.dtype == object:
        raise InputError(f"{name}: variable {var!r} holds a cell array or other objects, not "
                         "numbers; save it as a numeric vector")
    if arr.dtype == bool:  # a MATLAB logical: a mask or a flag saved by mistake
        raise InputError(f"{name}: variable {var!r} holds true/false values, not "
                         "measurements; save the signal itself (double(x) in MATLAB if "
                         "0 and 1 are meant)")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise InputError(f"{name}: variable {var!r} must hold real numbers, got {arr.dtype}")
    if arr.ndim != 1:
        if sum(s > 1 for s in arr.shape) > 1:
            raise InputError(
                f"{name}: variable {var!r} must be a vector, got shape {arr.shape}; store one "
                "vector per channel (or suffix _1, _2, ... per experiment)"
            )
        arr = arr.reshape(-1)
    return arr

def _sample_label(var: str) -> Callable[[int], str]:
    return lambda i: f"sample {i} (0-based) of {var!r}"

def _from_variables(name: str, variables: Mapping[str, Any], mapping: dict[str, str],
                    need: list[str], what: str) -> list[_Raw]:
    """Records from a flat set of named arrays (plain or suffixed names)."""
    want = {mapping[f]: f for f in mapping}
    # numbered channels (a shared plain time is allowed beside them)
    suffixed = sorted(v for v in variables if (m := _SUFFIX.match(v))
                      and m.group(1) in want and m.group(1) != mapping["t"])
    if all(mapping[f] in variables for f in need):
        if suffixed:  # one plain record and numbered ones: which did the user mean?
            raise InputError(
                f"{name}: holds both plain {what}s ({', '.join(mapping[f] for f in need)}) "
                f"and numbered ones ({', '.join(map(repr, suffixed[:4]))}"
                f"{', ...' if len(suffixed) > 4 else ''}); keep one naming scheme"
            )
        present = [f for f in mapping if mapping[f] in variables]
        cols = {f: _vector(name, mapping[f], variables[mapping[f]]) for f in present}
        prec = _precision(cols["t"]) if "t" in cols else 0.0
        var_t = mapping["t"]
        return [(name, {f: c.astype(float) for f, c in cols.items()}, _sample_label(var_t),
                 prec)]
    groups: dict[int, dict[str, str]] = {}
    for var in variables:
        m = _SUFFIX.match(var)
        if m and m.group(1) in want:
            groups.setdefault(int(m.group(2)), {})[want[m.group(1)]] = var
    if not groups:
        missing = [mapping[f] for f in need if mapping[f] not in variables]
        raise InputError(
            f"{name}: no {what} {', '.join(map(repr, missing))} (found: "
            f"{', '.join(map(repr, sorted(variables))) or 'none'}); name them "
            f"{', '.join(mapping[f] for f in need)} (or with suffixes _1, _2, ...), or map "
            "them with ", map_columns([f for f in need if mapping[f] not in variables]),
            *((" (or pass ", PASS_SAMPLE_TIME, " if there is no time)") if "t" in need else ())
        )
    out = []
    for k in sorted(groups):
        g = groups[k]
        if "t" not in g and mapping["t"] in variables:
            g["t"] = mapping["t"]
        missing = [f"{mapping[f]}_{k}" for f in need if f not in g]
        if missing:
            raise InputError(
                f"{name}: experiment _{k} has no {what} {', '.join(map(repr, missing))}; every "
                f"suffix needs {', '.join(mapping[f] for f in need if f != 't')} (and a time "
                f"{mapping['t']}_{k} or a shared {mapping['t']})"
            )
        cols = {f: _vector(name, g[f], variables[g[f]]) for f in g}
        prec = _precision(cols["t"]) if "t" in cols else 0.0
        out.append((f"{name}:_{k}", {f: c.astype(float) for f, c in cols.items()},
                    _sample_label(g.get("t", f"w_motor_{k}")), prec))
    return out

def _from_npz(name: str, mapping: dict[str, str], need: list[str]) -> list[_Raw]:
    if not zipfile.is_zipfile(name):  # else NumPy would talk of unpickling it
        raise InputError(f"{name}: not a NumPy .npz archive (no zip file); save the arrays "
                         "with numpy.savez, or give the file its real extension")
    try:
        with np.load(name, allow_pickle=False) as npz:
            variables = {k: npz[k] for k in npz.files}
    except ValueError as exc:
        raise InputError(
            f"{name}: cannot read the .npz archive ({exc}); save plain numeric arrays with "
            "numpy.savez"
        ) from None
    except (OSError, EOFError) as exc:
        raise InputError(f"{name}: not a NumPy .npz archive ({exc})") from None
    return _from_variables(name, variables, mapping, need, "array")

def _is_mat73(name: str) -> bool:
    with open(name, "rb") as fh:
        head = fh.read(520)
    return b"MATLAB 7.3" in head[:128] or head[512:520] == b"\x89HDF\r\n\x1a\n" or (
        head[:8] == b"\x89HDF\r\n\x1a\n"
    )

def _from_mat(name: str, mapping: dict[str, str], need: list[str]) -> list[_Raw]:
    if _is_mat73(name):
        return _from_mat73(name, mapping, need)
    from scipy import io as sio

    try:
        raw = sio.loadmat(name, squeeze_me=False, struct_as_record=True)
    except NotImplementedError:  # v7.3 not recognised by the header check
        return _from_mat73(name, mapping, need)
    except Exception as exc:  # scipy raises many types for a corrupt file
        raise InputError(
            f"{name}: not a readable MATLAB .mat file ({type(exc).__name__}: {exc}); save it "
            "with MATLAB's save (-v7 or -v7.3)"
        ) from None
    variables = {k: v for k, v in raw.items() if not k.startswith("__")}
    flat = {k: v for k, v in variables.items() if v.dtype.names is None}
    structs = {k: v for k, v in variables.items() if v.dtype.names is not None}
    fieldset = {mapping[f] for f in need}
    usable = {k: v for k, v in structs.items() if fieldset <= set(v.dtype.names)}
    if usable and not all(mapping[f] in flat for f in need):
        out = []
        for var in sorted(usable):
            arr = usable[var].reshape(-1, order="F")
            for i, elem in enumerate(arr):
                fields = {fn: elem[fn] for fn in arr.dtype.names}
                rec_name = f"{name}:{var}({i + 1})" if arr.size > 1 or len(usable) > 1 else name
                recs = _from_variables(rec_name, fields, mapping, need, f"field of {var!r}")
                out.extend(recs)
        return out
    _refuse_partial_struct(name, {k: set(v.dtype.names) for k, v in structs.items()}, flat,
                           mapping, need)
    return _from_variables(name, flat, mapping, need, "variable")

def _refuse_partial_struct(name: str, structs: dict[str, set[str]], flat, mapping,
                           need: list[str]) -> None:
    """A struct holding some of the channels but not all: name the missing fields."""
    if all(mapping[f] in flat for f in need):
        return
    for var, fields in sorted(structs.items()):
        have = [mapping[f] for f in need if mapping[f] in fields]
        if have:
            missing = [mapping[f] for f in need if mapping[f] not in fields]
            raise InputError(
                f"{name}: struct {var!r} has no field {', '.join(map(repr, missing))} (it has "
                f"{', '.join(map(repr, sorted(fields)))}); add the channel or map the names "
                "with ", map_columns([f for f in need if mapping[f] not in fields])
            )

def _from_mat73(name: str, mapping: dict[str, str], need: list[str]) -> list[_Raw]:
    try:
        import h5py
    except ImportError:
        raise InputError(
            f"{name}: a MATLAB v7.3 (HDF5) file needs the optional package h5py; install it "
            "(pip install h5py) or save the file with save(..., '-v7')"
        ) from None
    try:
        fh = h5py.File(name, "r")
    except OSError as exc:
        raise InputError(f"{name}: not a readable MATLAB v7.3 (HDF5) file ({exc})") from None
    with fh:
        flat: dict[str, np.ndarray] = {}
        odd: dict[str, str] = {}  # datasets that are no real numeric arrays -> what they are
        groups: dict[str, set[str]] = {}
        structs: dict[str, list[dict[str, np.ndarray]]] = {}
        for key, obj in fh.items():
            if key.startswith("#"):
                continue  # MATLAB's #refs# group
            if isinstance(obj, h5py.Dataset):
                if obj.dtype.kind in "iuf":
                    flat[key] = obj[()]
                elif obj.dtype.kind == "c" or (obj.dtype.names is not None
                                               and {"real", "imag"} <= set(obj.dtype.names)):
                    odd[key] = "complex numbers"  # MATLAB stores them as (real, imag)
                else:
                    odd[key] = ("a cell array" if obj.dtype == h5py.ref_dtype
                                else f"data of type {obj.dtype}")
            elif isinstance(obj, h5py.Group):
                groups[key] = set(obj.keys())
                elems = _h5_struct(fh, obj)
                if elems:
                    structs[key] = elems
    fieldset = {mapping[f] for f in need}
    usable = {k: e for k, e in structs.items() if all(fieldset <= set(x) for x in e)}
    if usable and not all(mapping[f] in flat for f in need):
        out = []
        for var in sorted(usable):
            elems = usable[var]
            for i, fields in enumerate(elems):
                rec_name = f"{name}:{var}({i + 1})" if len(elems) > 1 or len(usable) > 1 else name
                out.extend(_from_variables(rec_name, fields, mapping, need, f"field of {var!r}"))
        return out
    for f in need:
        if mapping[f] not in flat and mapping[f] in odd:
            raise InputError(
                f"{name}: variable {mapping[f]!r} holds {odd[mapping[f]]}, not real numbers; "
                "save it as a real numeric array"
            )
    _refuse_partial_struct(name, groups, flat, mapping, need)
    return _from_variables(name, flat, mapping, need, "variable")

def _h5_struct(fh, group) -> list[dict[str, np.ndarray]]:
    """Elements of a v7.3 struct: fields are datasets (scalar) or references (array)."""
    import h5py

    fields = {k: d for k, d in group.items() if isinstance(d, h5py.Dataset)}
    if not fields:
        return []
    if all(d.dtype.kind in "iuf" for d in fields.values()):
        return [{k: d[()] for k, d in fields.items()}]
    if all(d.dtype == h5py.ref_dtype for d in fields.values()):
        refs = {k: np.asarray(d[()]).reshape(-1, order="F") for k, d in fields.items()}
        n = {r.size for r in refs.values()}
        if len(n) != 1:
            return []
        return [{k: fh[r[i]][()] for k, r in refs.items()} for i in range(n.pop())]
    return []
