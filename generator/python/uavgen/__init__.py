"""uavgen from Python: flight logs, identified quadrotor models, evaluation, diagnosis, the plant
simulator and closed loops, and generated no_std MPC crates.

Every function runs the same library code as the matching ``uavgen`` command (the Rust crate
``uavgen`` built with its ``python`` feature, the extension module ``uavgen._uavgen``), so results
and error messages are the CLI's: errors raise :class:`UavgenError` with the message the CLI prints
(naming the file, field and line). Nothing draws progress bars; notes the CLI prints on stderr are
issued as :class:`UavgenWarning` through :mod:`warnings`. See docs/python.md.
"""

from __future__ import annotations

import json as _json
import os
import warnings as _warnings
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _uavgen
from ._uavgen import UavgenError, __version__

PathLike = Union[str, "os.PathLike[str]"]

#: The 12 states of a flight log, in the order of ``Log`` arrays (docs/log-format.md).
STATE_COLUMNS: Tuple[str, ...] = (
    "x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate",
)
#: The 4 inputs of a flight log, in the order of ``Log`` arrays.
INPUT_COLUMNS: Tuple[str, ...] = ("u_vz", "u_roll", "u_pitch", "u_yaw_rate")

__all__ = [
    "UavgenError", "UavgenWarning", "Model", "Log", "read_log", "import_log", "evaluate", "simulate",
    "track", "diagnose", "generate", "identify", "STATE_COLUMNS", "INPUT_COLUMNS", "__version__",
]


class UavgenWarning(UserWarning):
    """A note or warning the CLI prints on stderr (a log outside the model's envelope, a data
    quality problem, a diagnosis caveat)."""


def _warn(messages: Iterable[str]) -> None:
    for m in messages:
        _warnings.warn(m, UavgenWarning, stacklevel=3)


def _f64(a: Any, name: str) -> np.ndarray:
    try:
        return np.ascontiguousarray(np.asarray(a, dtype=np.float64))
    except (TypeError, ValueError) as e:
        raise UavgenError(f"{name}: not an array of numbers: {e}") from None


def _path(p: PathLike) -> str:
    return os.fspath(p)


# ------------------------------------------------------------------------------------------ models


class Model:
    """A validated ``uavgen-model/1`` model (docs/model-format.md): ẋ = f(x, u) with exact
    Jacobians, evaluated by the library's interpreter.

    Build one with :meth:`load`, :meth:`from_json`, :func:`identify`, :func:`diagnose` (the
    corrected model) or ``Model.from_pysindy``.
    """

    __slots__ = ("_inner",)

    def __init__(self, inner: "_uavgen.Model"):
        if not isinstance(inner, _uavgen.Model):
            raise TypeError("use Model.load, Model.from_json or uavgen.identify to make a Model")
        self._inner = inner

    @classmethod
    def load(cls, path: PathLike) -> "Model":
        """Read and validate a model file (errors name the path, the field and the line)."""
        return cls(_uavgen.Model.load(_path(path)))

    @classmethod
    def from_json(cls, text: str, name_for_errors: str = "<model>") -> "Model":
        """Validate model text; ``name_for_errors`` names it in errors as a file name would."""
        return cls(_uavgen.Model.from_json(text, name_for_errors))

    def to_json(self) -> str:
        """The model file's text (as read, or as identify/diagnose produced it)."""
        return self._inner.to_json()

    def save(self, path: PathLike, force: bool = False) -> None:
        """Write the model file (atomically); an existing file is replaced only with ``force``."""
        self._inner.save(_path(path), force)

    @property
    def name(self) -> str:
        return self._inner.name

    @property
    def kind(self) -> str:
        """``"sindy"`` or ``"pd"``."""
        return self._inner.kind

    @property
    def states(self) -> List[str]:
        """All states: the file's, then the extra states of a ``corrections`` block."""
        return self._inner.states

    @property
    def inputs(self) -> List[str]:
        return self._inner.inputs

    @property
    def nx(self) -> int:
        return len(self._inner.states)

    @property
    def nu(self) -> int:
        return len(self._inner.inputs)

    @property
    def input_delays(self) -> List[float]:
        """Pure delay of each input in s (``corrections.latency``; not part of f)."""
        return self._inner.input_delays

    @property
    def source(self) -> str:
        """What errors and reports name the model by (the path it was read from, or a label)."""
        return self._inner.label

    @property
    def sha256(self) -> str:
        return self._inner.sha256

    def _xu(self, x: Any, u: Any) -> Tuple[np.ndarray, np.ndarray, Tuple[int, ...]]:
        x, u = _f64(x, "x"), _f64(u, "u")
        if x.ndim == 0 or x.shape[-1] != self.nx:
            raise UavgenError(f"x: the last axis must hold the model's {self.nx} states, got shape {x.shape}")
        if u.ndim == 0 or u.shape[-1] != self.nu:
            raise UavgenError(f"u: the last axis must hold the model's {self.nu} inputs, got shape {u.shape}")
        try:
            lead = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
        except ValueError:
            raise UavgenError(f"x {x.shape} and u {u.shape}: the leading axes do not broadcast") from None
        x = np.ascontiguousarray(np.broadcast_to(x, lead + (self.nx,)))
        u = np.ascontiguousarray(np.broadcast_to(u, lead + (self.nu,)))
        return x, u, lead

    def f(self, x: Any, u: Any) -> np.ndarray:
        """ẋ = f(x, u). ``x`` (..., NX) and ``u`` (..., NU) broadcast over their leading axes; the
        result has shape (..., NX)."""
        x, u, lead = self._xu(x, u)
        n = int(np.prod(lead, dtype=np.int64))
        out = self._inner.f(x.tobytes(), u.tobytes(), n)
        return np.frombuffer(out, dtype=np.float64).reshape(lead + (self.nx,)).copy()

    def jacobians(self, x: Any, u: Any) -> Tuple[np.ndarray, np.ndarray]:
        """(∂f/∂x, ∂f/∂u), exact (symbolic), of shapes (..., NX, NX) and (..., NX, NU)."""
        x, u, lead = self._xu(x, u)
        n = int(np.prod(lead, dtype=np.int64))
        a, b = self._inner.jacobians(x.tobytes(), u.tobytes(), n)
        return (
            np.frombuffer(a, dtype=np.float64).reshape(lead + (self.nx, self.nx)).copy(),
            np.frombuffer(b, dtype=np.float64).reshape(lead + (self.nx, self.nu)).copy(),
        )

    def auto_substeps(self, dt: float) -> int:
        """RK4 substeps per sample of ``dt`` s by the automatic rule (docs/discretisation.md)."""
        return self._inner.auto_substeps(float(dt))

    def simulate(self, x0: Any, U: Any, dt: float, substeps: Optional[int] = None) -> np.ndarray:
        """Free run from ``x0`` (NX) under the inputs ``U`` (steps × NU), each held over one
        sample of ``dt`` s: fixed-step RK4 with ``substeps`` substeps per sample (default: the
        automatic rule), the generated crate's and ``uavgen evaluate``'s discretisation, run in
        Rust. Returns the states (steps + 1) × NX, ``x0`` first. Input delays
        (``corrections.latency``) are not applied: shift ``U`` for them."""
        x0 = _f64(x0, "x0").reshape(-1)
        U = _f64(U, "U")
        if U.ndim == 1 and self.nu == U.shape[0]:
            U = U.reshape(1, -1)
        if U.ndim != 2 or U.shape[1] != self.nu:
            raise UavgenError(f"U: expected shape (steps, {self.nu}), got {U.shape}")
        out, _ = self._inner.simulate(x0.tobytes(), U.tobytes(), U.shape[0], float(dt), substeps)
        return np.frombuffer(out, dtype=np.float64).reshape(U.shape[0] + 1, self.nx).copy()

    def __repr__(self) -> str:
        return repr(self._inner)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Model) and self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]


def _model(model: Union[Model, PathLike]) -> Model:
    if isinstance(model, Model):
        return model
    if isinstance(model, (str, os.PathLike)):
        return Model.load(model)
    raise TypeError(f"expected a uavgen.Model or a model file path, got {type(model).__name__}")


# -------------------------------------------------------------------------------------------- logs


class Log:
    """A validated flight log (docs/log-format.md): segments of time ``t`` (n), states ``x``
    (n × 12, yaw unwrapped) and inputs ``u`` (n × 4), read by the library's log reader.

    Build one with :func:`read_log`, :func:`import_log`, :meth:`from_numpy`, :meth:`from_pandas`,
    :meth:`from_csv` or :func:`simulate`.
    """

    __slots__ = ("_inner",)

    def __init__(self, inner: "_uavgen.Log"):
        if not isinstance(inner, _uavgen.Log):
            raise TypeError("use uavgen.read_log, Log.from_numpy or Log.from_pandas to make a Log")
        self._inner = inner

    @classmethod
    def from_csv(cls, text: str, name: str = "<csv>") -> "Log":
        """Validate CSV text of the log contract; ``name`` is its source in errors and reports."""
        return cls(_uavgen.Log.from_csv(text, name))

    @classmethod
    def from_numpy(
        cls,
        t: Any,
        x: Any,
        u: Any,
        segment: Any = None,
        battery_voltage: Any = None,
        rate_hz: Optional[float] = None,
        metadata: Optional[Dict[str, Any]] = None,
        name: str = "<numpy>",
    ) -> "Log":
        """A log from arrays: ``t`` (n,) in s, ``x`` (n, 12) in STATE_COLUMNS order, ``u`` (n, 4) in
        INPUT_COLUMNS order; optional ``segment`` (n integers), ``battery_voltage`` (n), the
        ``# rate_hz`` metadata and other ``# key: value`` metadata. The arrays are written as the
        contract's CSV and read by the same reader as a file (same checks, same messages, with
        line numbers counting the metadata lines and the header)."""
        t = _f64(t, "t").reshape(-1)
        x, u = _f64(x, "x"), _f64(u, "u")
        n = t.shape[0]
        if x.shape != (n, 12):
            raise UavgenError(f"x: expected shape ({n}, 12), got {x.shape}")
        if u.shape != (n, 4):
            raise UavgenError(f"u: expected shape ({n}, 4), got {u.shape}")
        seg = None
        if segment is not None:
            seg = [int(s) for s in np.asarray(segment).reshape(-1)]
        bat = None if battery_voltage is None else _f64(battery_voltage, "battery_voltage").reshape(-1).tobytes()
        meta: List[Tuple[str, str]] = []
        if rate_hz is not None:
            meta.append(("rate_hz", repr(float(rate_hz))))
        for k, v in (metadata or {}).items():
            meta.append((str(k), str(v)))
        return cls(_uavgen.Log.from_arrays(t.tobytes(), x.tobytes(), u.tobytes(), n, seg, bat, meta, name))

    @classmethod
    def from_pandas(cls, df: Any, rate_hz: Optional[float] = None, metadata: Optional[Dict[str, Any]] = None,
                    name: str = "<pandas>") -> "Log":
        """A log from a DataFrame with the contract's columns (``t``, the 12 states, the 4
        inputs; optional ``battery_voltage`` and ``segment``)."""
        missing = [c for c in ("t",) + STATE_COLUMNS + INPUT_COLUMNS if c not in df.columns]
        if missing:
            raise UavgenError(f"{name}: missing column(s) {', '.join(missing)}")
        return cls.from_numpy(
            df["t"].to_numpy(),
            df[list(STATE_COLUMNS)].to_numpy(),
            df[list(INPUT_COLUMNS)].to_numpy(),
            segment=df["segment"].to_numpy() if "segment" in df.columns else None,
            battery_voltage=df["battery_voltage"].to_numpy() if "battery_voltage" in df.columns else None,
            rate_hz=rate_hz,
            metadata=metadata,
            name=name,
        )

    @property
    def source(self) -> str:
        """What errors and reports name the log by (the path as given, or the name)."""
        return self._inner.source

    @property
    def metadata(self) -> Dict[str, str]:
        """The ``# key: value`` lines (the first of each key)."""
        out: Dict[str, str] = {}
        for k, v in self._inner.metadata:
            out.setdefault(k, v)
        return out

    @property
    def rows(self) -> int:
        return self._inner.rows

    def __len__(self) -> int:
        return self._inner.rows

    @property
    def warnings(self) -> List[str]:
        """The data-quality report's warnings (sampling, rate, stale rows; docs/logs.md)."""
        return self._inner.warnings()

    @property
    def segments(self) -> List[Dict[str, Any]]:
        """One dict per segment: ``t``, ``x``, ``u``, ``battery_voltage`` (or None), ``first_line``."""
        out = []
        for i in range(self._inner.segment_count):
            t, x, u, b, n, line = self._inner.segment(i)
            out.append({
                "t": np.frombuffer(t, dtype=np.float64).copy(),
                "x": np.frombuffer(x, dtype=np.float64).reshape(n, 12).copy(),
                "u": np.frombuffer(u, dtype=np.float64).reshape(n, 4).copy(),
                "battery_voltage": None if b is None else np.frombuffer(b, dtype=np.float64).copy(),
                "first_line": line,
            })
        return out

    def to_numpy(self) -> Dict[str, Any]:
        """All segments concatenated: ``t`` (n,), ``x`` (n, 12), ``u`` (n, 4), ``segment`` (n,
        the segment index) and ``battery_voltage`` (n, or None)."""
        segs = self.segments
        bat = None
        if segs and all(s["battery_voltage"] is not None for s in segs):
            bat = np.concatenate([s["battery_voltage"] for s in segs])
        return {
            "t": np.concatenate([s["t"] for s in segs]) if segs else np.zeros(0),
            "x": np.concatenate([s["x"] for s in segs]) if segs else np.zeros((0, 12)),
            "u": np.concatenate([s["u"] for s in segs]) if segs else np.zeros((0, 4)),
            "segment": np.concatenate([np.full(len(s["t"]), i, dtype=np.int64) for i, s in enumerate(segs)])
            if segs else np.zeros(0, dtype=np.int64),
            "battery_voltage": bat,
        }

    def to_pandas(self) -> Any:
        """A DataFrame with the contract's columns and ``segment`` (needs pandas)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("Log.to_pandas needs pandas: pip install pandas") from None
        a = self.to_numpy()
        cols: Dict[str, Any] = {"t": a["t"]}
        for i, c in enumerate(STATE_COLUMNS):
            cols[c] = a["x"][:, i]
        for i, c in enumerate(INPUT_COLUMNS):
            cols[c] = a["u"][:, i]
        if a["battery_voltage"] is not None:
            cols["battery_voltage"] = a["battery_voltage"]
        cols["segment"] = a["segment"]
        return pd.DataFrame(cols)

    def to_csv(self) -> str:
        """The log as the contract's CSV text (yaw unwrapped, a ``segment`` column)."""
        return self._inner.to_csv()

    def save(self, path: PathLike, force: bool = False) -> None:
        """Write :meth:`to_csv` to ``path``; an existing file is replaced only with ``force``."""
        p = _path(path)
        if os.path.exists(p) and not force:
            raise UavgenError(f"{p}: exists; pass force=True to overwrite it")
        tmp = p + ".uavgen-tmp"
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(self.to_csv())
        os.replace(tmp, p)

    def __repr__(self) -> str:
        return repr(self._inner)


def read_log(path: PathLike, profile: Optional[str] = None) -> Log:
    """Read a flight log as ``--log`` of identify, evaluate and diagnose does: a CSV of the
    contract, or (with ``profile``) a PX4 ULog, MCAP, ROS 1 bag, DataFlash log or a CSV of another
    schema (docs/import.md). Angles that look like degrees are refused."""
    return Log(_uavgen.Log.load(_path(path), profile))


def import_log(path: PathLike, profile: str) -> Log:
    """Import a recording (PX4 ULog, MCAP, ROS 1 bag, ArduPilot DataFlash, other CSV) mapped by
    ``profile``: a preset (px4, mavros, dji-osdk-ros, ardupilot) or a profile file."""
    if not profile:
        raise UavgenError("profile: a preset (px4, mavros, dji-osdk-ros, ardupilot) or a profile file is needed")
    return read_log(path, profile)


def _logs(logs: Any, profile: Optional[str] = None) -> List["_uavgen.Log"]:
    if isinstance(logs, (Log, str, os.PathLike)):
        logs = [logs]
    out = []
    for entry in logs:
        if isinstance(entry, Log):
            out.append(entry._inner)
        elif isinstance(entry, (str, os.PathLike)):
            out.append(read_log(entry, profile)._inner)
        else:
            raise TypeError(f"expected a uavgen.Log or a log file path, got {type(entry).__name__}")
    return out


def _mpc_json(mpc: Any, mpc_options: Dict[str, Any]) -> Optional[str]:
    """MPC options (docs/mpc.md) as the text of an options file: a path, a dict, keyword options."""
    base: Dict[str, Any] = {}
    if isinstance(mpc, (str, os.PathLike)):
        with open(_path(mpc), encoding="utf-8") as fh:
            text = fh.read()
        if not mpc_options:
            return text
        base = _json.loads(text)
    elif isinstance(mpc, dict):
        base = dict(mpc)
    elif mpc is not None:
        raise TypeError("mpc: a path to an MPC options file or a dict")
    base.update(mpc_options)
    if not base and mpc is None:
        return None

    def plain(v: Any) -> Any:
        return v.tolist() if isinstance(v, np.ndarray) else v

    return _json.dumps({k: plain(v) for k, v in base.items()})


# ---------------------------------------------------------------------------------------- commands


def evaluate(model: Union[Model, PathLike], logs: Any, horizon: int = 30, substeps: Optional[int] = None,
             stale: str = "interpolate", profile: Optional[str] = None, plots: Optional[PathLike] = None,
             json: Optional[PathLike] = None, force: bool = False) -> Dict[str, Any]:
    """``uavgen evaluate``: one-step, horizon and whole-flight predictions of ``model`` against
    ``logs`` (Logs or paths, read with ``profile``). Returns the dict ``--json`` writes (equal to
    it); ``json`` also writes it, ``plots`` writes the measured-vs-predicted SVGs into a
    directory. Notes on logs outside the model's envelope are issued as UavgenWarning."""
    if json is not None and os.path.exists(_path(json)) and not force:
        raise UavgenError(f"{_path(json)}: exists; pass force=True to overwrite it")
    m = _model(model)
    text, _summary, notes, _files = _uavgen.evaluate(
        m._inner, _logs(logs, profile), horizon, substeps, stale, None if plots is None else _path(plots)
    )
    _warn(notes)
    if json is not None:
        tmp = _path(json) + ".uavgen-tmp"
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, _path(json))
    return _json.loads(text)


def _durations(v: Any) -> str:
    if isinstance(v, (list, tuple)):
        return ",".join(_durations(d) for d in v)
    return str(v)


def simulate(plant: PathLike, profile: Union[str, Sequence[str]] = "excite", duration: Any = 60, seed: int = 1,
             out: Optional[PathLike] = None, force: bool = False) -> Log:
    """``uavgen simulate``: fly ``profile`` (or a list, one segment each: excite,
    excite-hold-heading, hover, circle, sinusoid, spiral) for ``duration`` seconds (a number or a
    list as long) with the plant file, seeded by ``seed``. Returns the log; ``out`` also writes it
    (the file ``uavgen simulate --out`` writes)."""
    profiles = profile if isinstance(profile, str) else ",".join(profile)
    return Log(_uavgen.simulate(_path(plant), profiles, _durations(duration), seed,
                                None if out is None else _path(out), force))


def _columns(csv_text: str) -> Dict[str, np.ndarray]:
    lines = csv_text.splitlines()
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:] if line]
    out: Dict[str, np.ndarray] = {}
    for i, name in enumerate(header):
        values = [r[i] for r in rows]
        try:
            out[name] = np.array([float(v) for v in values])
        except ValueError:
            out[name] = np.array(values)
    return out


def track(model: Union[Model, PathLike], plant: PathLike, trajectory: Union[str, Sequence[str]] = "circle",
          duration: float = 30.0, seed: int = 1, horizon: int = 30, mpc: Any = None, generic: bool = False,
          max_rmse: float = 0.30, max_distance: float = 20.0, work_dir: PathLike = "target/uavgen-track",
          out: Optional[PathLike] = None, force: bool = False, **mpc_options: Any) -> Dict[str, Dict[str, Any]]:
    """``uavgen track``: closed-loop MPC on the plant simulator along the paper's trajectories
    (circle, sinusoid, spiral; a name or a list). The MPC is the generated crate in the tracking
    harness (built with cargo in ``work_dir``), or with ``generic=True`` the generic reference
    solver. Returns per trajectory ``{"report": report.json as a dict, "samples": samples.csv's
    columns as arrays, "summary": the line the CLI prints}``; ``out`` also writes the CLI's files."""
    names = [trajectory] if isinstance(trajectory, str) else list(trajectory)
    m = _model(model)
    results = _uavgen.track(m._inner, _path(plant), names, float(duration), seed, horizon,
                            _mpc_json(mpc, mpc_options), generic, float(max_rmse), float(max_distance),
                            _path(work_dir), None if out is None else _path(out), force)
    out_dict: Dict[str, Dict[str, Any]] = {}
    for name, (report, samples, line) in zip(names, results):
        out_dict[name] = {"report": _json.loads(report), "samples": _columns(samples), "summary": line}
    return out_dict


def diagnose(model: Union[Model, PathLike], logs: Any, holdout: Any = (), out: Optional[PathLike] = None,
             force: bool = False, profile: Optional[str] = None, horizon: int = 30,
             substeps: Optional[int] = None, rotor_radius: float = 0.1651, gravity: Optional[float] = None,
             effects: Optional[Sequence[str]] = None, max_effects: int = 3, max_delta_bic: float = -10.0,
             min_reduction: float = 0.03, min_z: float = 3.0, savgol_window: int = 9, savgol_order: int = 3,
             plant: Optional[PathLike] = None, mpc: Optional[PathLike] = None, pointwise: bool = False,
             where: bool = True, stale: str = "interpolate") -> Tuple[Dict[str, Any], Model]:
    """``uavgen diagnose``: where ``model`` parts from the ``logs``, which catalogued effect explains
    it, and the corrected model. Scored on ``holdout`` logs (else cross-validation). Returns
    (report.json as a dict, the corrected Model); ``out`` also writes the CLI's directory. The
    diagnosis's warnings are issued as UavgenWarning."""
    m = _model(model)
    report, corrected, warns, _files = _uavgen.diagnose(
        m._inner, _logs(logs, profile), _logs(holdout, profile), None if out is None else _path(out), force,
        horizon, substeps, float(rotor_radius), gravity, None if effects is None else list(effects), max_effects,
        float(max_delta_bic), float(min_reduction), float(min_z), savgol_window, savgol_order,
        None if plant is None else _path(plant), None if mpc is None else _path(mpc), pointwise, where, stale,
    )
    _warn(warns)
    return _json.loads(report), Model.from_json(corrected, "corrected.json")


def generate(model: Union[Model, PathLike], horizon: int = 30, out: Optional[PathLike] = None, c_api: bool = False,
             force: bool = False, rate: float = 30.0, substeps: Optional[int] = None, float: str = "f64",
             qp: str = "auto", crate_name: Optional[str] = None, mpc: Any = None,
             **mpc_options: Any) -> Dict[str, Any]:
    """``uavgen --model … --horizon …``: generate the model's no_std MPC crate into ``out``
    (default ``./<crate name>``). MPC options (docs/mpc.md) come from ``mpc`` (a file or a dict)
    and keyword arguments (``q=[…]``, ``r_delta=[…]``, ``max_qp_iterations=…``). Returns the crate
    name, the directory, the RK4 substeps per sample and the CLI's summary lines."""
    m = _model(model)
    name, directory, substeps_used, summary = _uavgen.generate(
        m.to_json(), horizon, None if out is None else _path(out), c_api, _mpc_json(mpc, mpc_options), force,
        rate, substeps, float, qp, crate_name, m.source,
    )
    return {"crate_name": name, "out": directory, "substeps": substeps_used, "summary": summary}


def identify(logs: Any, method: str = "sindy", out: Optional[PathLike] = None, name: Optional[str] = None,
             force: bool = False, profile: Optional[str] = None, savgol_window: Optional[int] = None,
             savgol_order: int = 3, library: str = "physics", all_rows: bool = False, optimizer: str = "stlsq",
             threshold: Optional[float] = None, sweep: bool = False, sweep_values: Optional[Sequence[float]] = None,
             alpha: Optional[float] = None, horizon_check: bool = True, criterion: str = "bic",
             input_delay: Any = "auto", stale: str = "interpolate", targets: Optional[str] = None,
             refine_loops: Union[bool, str] = True, mass: float = 2.4, lowpass: Optional[float] = None,
             max_rate: float = 100.0, progress: bool = False) -> Model:
    """``uavgen identify``: a SINDy (``method="sindy"``) or PD (``"pd"``) model from flight logs
    (Logs or paths, read with ``profile``), with the CLI's defaults. The keyword arguments are the
    CLI's flags (``--savgol-window`` is ``savgol_window``, ``--no-horizon-check`` is
    ``horizon_check=False``, ``--refine-loops none`` is ``refine_loops=False``, ``--max-rate`` is
    ``max_rate``; ``input_delay`` is
    ``"auto"``, ``"none"``, seconds, or ``"u_vz=0.13,…"``). The model is named ``name``, else
    ``out``'s stem, else ``identified``; ``out`` also writes the file (byte for byte what
    ``uavgen identify --out`` writes). Warnings are issued as UavgenWarning; with
    ``progress=True`` the CLI's messages are printed on stderr as they come."""
    if out is not None and os.path.exists(_path(out)) and not force:
        raise UavgenError(f"{_path(out)}: exists; pass force=True to overwrite it")
    if name is None:
        name = os.path.splitext(os.path.basename(_path(out)))[0] if out is not None else "identified"
    if isinstance(refine_loops, str):
        if refine_loops not in ("auto", "none"):
            raise UavgenError(f"refine_loops: `{refine_loops}` is not one of auto, none")
        refine_loops = refine_loops == "auto"
    if not isinstance(input_delay, str):
        input_delay = repr(float(input_delay))
    text, warns, _lines = _uavgen.identify(
        _logs(logs, profile), method, name, None if out is None else _path(out), savgol_window, savgol_order,
        library, all_rows, optimizer, threshold, sweep, None if sweep_values is None else [float(v) for v in sweep_values],
        alpha, horizon_check, criterion, input_delay, stale, targets, bool(refine_loops), float(mass), lowpass,
        float(max_rate), progress,
    )
    _warn(warns)
    if out is None:
        return Model.from_json(text, name)
    tmp = _path(out) + ".uavgen-tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, _path(out))
    return Model.load(out)


# The PySINDy bridge and the compiled solver (generator/python/uavgen/pysindy.py, compile.py).
from .pysindy import from_pysindy as _from_pysindy  # noqa: E402
from .compile import (  # noqa: E402,F401
    CargoNotFoundError,
    CompileError,
    Controller,
    Mpc,
    MpcError,
    Status,
    compile,
)

Model.from_pysindy = staticmethod(_from_pysindy)  # type: ignore[attr-defined]
__all__ += ["compile", "Mpc", "Controller", "Status", "CompileError", "CargoNotFoundError", "MpcError"]
