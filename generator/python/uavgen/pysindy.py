"""A fitted PySINDy model as a uavgen ``Model``: ``from_pysindy`` (``Model.from_pysindy``).

PySINDy (https://github.com/dynamicslab/pysindy) stores a fitted model as its feature names
(``model.get_feature_names()``) and a coefficient matrix (``model.coefficients()``, one row per state
column of ``x``, one column per feature). A continuous-time model with control fitted as
``model.fit(x, t=t, u=u, feature_names=names)`` predicts ẋ = Ξ Θ(x, u); this module turns it into a
``uavgen-model/1`` ``kind: "sindy"`` model (docs/model-format.md) directly, without the export
script and ``uavgen import-pysindy`` (scripts/export_pysindy.py, which stays for files):

- **states** are the columns of ``x`` (``model.feature_names[:n]``, ``n`` = coefficient rows), **inputs**
  the columns of ``u`` (the rest); ``state_names=`` / ``input_names=`` rename them (every term is
  rewritten with the new names);
- **every row** is one state's derivative, so ``Model.f(x, u)`` is PySINDy's ``predict(x, u)`` (no
  ``kinematic`` rows: PySINDy fitted them or not, as its user chose);
- the **library** is PySINDy's feature names read with uavgen's term grammar: products by whitespace or
  ``*``, powers ``^k``, ``sin(v)``/``cos(v)`` of one variable, and the ``FourierLibrary``'s
  frequency-1 names ``sin(1 v)`` (written ``sin(v)``). A feature outside the grammar (another
  frequency, a ``CustomLibrary`` function without ``function_names``, PDE derivatives) is an error
  if a coefficient uses it and is left out of the library (listed in
  ``provenance.dropped_unused_features``) if none does;
- features that are the same term (``GeneralizedLibrary`` of two libraries with a bias each, ``x0``
  from an ``IdentityLibrary`` and a ``PolynomialLibrary``) are one library term: their coefficients are
  added;
- exact zeros of Ξ (PySINDy's thresholded entries) are not written.

The hook that makes it ``Model.from_pysindy`` is one line in ``uavgen/__init__.py``::

    Model.from_pysindy = staticmethod(pysindy.from_pysindy)
"""

from __future__ import annotations

import json
import re
from typing import Dict, List, Optional, Sequence, Tuple

__all__ = ["from_pysindy", "pysindy_to_model_json", "PySindyConversionError"]

TOOL = "uavgen.from_pysindy"

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")

# One factor of a PySINDy feature name: sin(v) / cos(v) / sin(1 v) / a variable, optionally ^k.
_FACTOR = re.compile(
    r"""
    (?:
        (?P<fn>sin|cos)\s*\(\s*(?:(?P<freq>[0-9]+(?:\.[0-9]*)?)\s*\*?\s*)?(?P<arg>[A-Za-z_][A-Za-z0-9_]*)\s*\)
      | (?P<var>[A-Za-z_][A-Za-z0-9_]*)(?![A-Za-z0-9_]|\s*\()
    )
    (?:\s*\^\s*(?P<pow>[0-9]+))?
    """,
    re.VERBOSE,
)


class PySindyConversionError(ValueError):
    """A fitted PySINDy model that cannot be written as a uavgen model (the message says why)."""


Factor = Tuple[str, str, int]  # (kind: "var" | "sin" | "cos", variable, power)


def _parse_feature(feature: str, variables: Sequence[str]) -> Optional[List[Factor]]:
    """The factors of one PySINDy feature name; [] for the constant "1"; None if outside the grammar.

    Raises nothing: the caller decides whether an unreadable feature is an error (used) or is dropped.
    """
    s = feature.strip()
    if s == "1":
        return []
    factors: List[Factor] = []
    pos = 0
    known = set(variables)
    while pos < len(s):
        m = _FACTOR.match(s, pos)
        if m is None:
            return None
        if m.group("fn"):
            freq = m.group("freq")
            if freq is not None and float(freq) != 1.0:
                return None
            kind, var = m.group("fn"), m.group("arg")
        else:
            kind, var = "var", m.group("var")
        if var not in known:
            return None
        power = int(m.group("pow")) if m.group("pow") else 1
        if not 1 <= power <= 16:
            return None
        factors.append((kind, var, power))
        pos = m.end()
        # Separator: whitespace and/or one '*', or the end.
        sep = re.compile(r"\s*\*\s*|\s+").match(s, pos)
        if sep is not None and sep.end() > pos:
            pos = sep.end()
            if pos >= len(s):
                return None  # a trailing '*'
        elif pos < len(s):
            return None
    return factors or None


def _term_string(factors: List[Factor], rename: Dict[str, str]) -> str:
    """uavgen's spelling of the factors (as written, renamed), joined by '*'."""
    if not factors:
        return "1"
    parts = []
    for kind, var, power in factors:
        base = rename[var] if kind == "var" else f"{kind}({rename[var]})"
        parts.append(base if power == 1 else f"{base}^{power}")
    return "*".join(parts)


def _canonical(factors: List[Factor], order: Dict[str, int]) -> Tuple:
    """The canonical form uavgen compares terms by (docs/model-format.md, "Term grammar"): plain
    variables, then sin, then cos, each by variable order, repeated bases merged."""
    merged: Dict[Tuple[int, int], int] = {}
    kinds = {"var": 0, "sin": 1, "cos": 2}
    for kind, var, power in factors:
        key = (kinds[kind], order[var])
        merged[key] = merged.get(key, 0) + power
    return tuple(sorted(merged.items()))


def _check_names(kind: str, names: Sequence[str]) -> List[str]:
    out = []
    for i, n in enumerate(names):
        if not isinstance(n, str) or not _NAME.match(n) or n in ("sin", "cos"):
            raise PySindyConversionError(
                f"{kind}[{i}] = {n!r} is not a uavgen variable name (ASCII letters, digits and _, "
                f"not starting with a digit, not sin or cos): pass {kind}= to from_pysindy, or "
                f"feature_names= to SINDy.fit"
            )
        out.append(n)
    return out


def pysindy_to_model_json(
    model,
    state_names: Optional[Sequence[str]] = None,
    input_names: Optional[Sequence[str]] = None,
    name: str = "pysindy",
) -> str:
    """The ``uavgen-model/1`` JSON text of a fitted ``pysindy.SINDy`` model (module docs).

    Pure Python: it needs neither the compiled extension nor PySINDy itself beyond the model
    object (``coefficients()``, ``get_feature_names()``, ``feature_names``,
    ``n_control_features_``).
    """
    kind = type(model).__name__
    if "Discrete" in kind or getattr(model, "discrete_time", False):
        raise PySindyConversionError(
            f"from_pysindy: {kind} is a discrete-time model (x[k+1] = f(x[k], u[k])); uavgen models "
            f"are continuous-time ẋ = f(x, u): fit a continuous-time pysindy.SINDy"
        )
    for attr in ("coefficients", "get_feature_names"):
        if not callable(getattr(model, attr, None)):
            raise PySindyConversionError(
                f"from_pysindy: expected a fitted pysindy.SINDy model, got {kind} (no {attr}())"
            )
    try:
        import numpy as np

        coefficients = np.asarray(model.coefficients(), dtype=float)
        features = [str(f) for f in model.get_feature_names()]
    except Exception as e:  # sklearn's NotFittedError and friends
        raise PySindyConversionError(f"from_pysindy: the model is not fitted ({e})") from e
    if coefficients.ndim != 2 or coefficients.shape[1] != len(features):
        raise PySindyConversionError(
            f"from_pysindy: coefficients of shape {coefficients.shape} for {len(features)} feature names"
        )
    n_states = coefficients.shape[0]
    variables = [str(v) for v in (getattr(model, "feature_names", None) or [])]
    n_inputs = int(getattr(model, "n_control_features_", 0) or 0)
    if len(variables) != n_states + n_inputs:
        raise PySindyConversionError(
            f"from_pysindy: the model has {len(variables)} variables ({', '.join(variables)}) for "
            f"{n_states} states (coefficient rows) and {n_inputs} control inputs"
        )
    states = list(variables[:n_states]) if state_names is None else list(state_names)
    inputs = list(variables[n_states:]) if input_names is None else list(input_names)
    if len(states) != n_states:
        raise PySindyConversionError(
            f"from_pysindy: {len(states)} state_names for {n_states} states (the columns of x the "
            f"model was fitted on: {', '.join(variables[:n_states])})"
        )
    if len(inputs) != n_inputs:
        raise PySindyConversionError(
            f"from_pysindy: {len(inputs)} input_names for {n_inputs} control inputs (the columns of u "
            f"the model was fitted on: {', '.join(variables[n_states:]) or 'none'})"
        )
    _check_names("state_names", states)
    _check_names("input_names", inputs)
    if len(set(states + inputs)) != len(states) + len(inputs):
        raise PySindyConversionError("from_pysindy: state and input names must be unique")
    if not np.all(np.isfinite(coefficients)):
        row, col = map(int, np.argwhere(~np.isfinite(coefficients))[0])
        raise PySindyConversionError(
            f"from_pysindy: coefficient of '{features[col]}' in the row of {states[row]} is "
            f"{coefficients[row, col]}"
        )
    rename = dict(zip(variables, states + inputs))
    order = {v: i for i, v in enumerate(variables)}

    library: List[str] = []
    column_of_key: Dict[Tuple, int] = {}
    merged = []  # per library term: summed coefficient column
    dropped = []
    for j, feature in enumerate(features):
        factors = _parse_feature(feature, variables)
        used = bool(np.any(coefficients[:, j] != 0.0))
        if factors is None:
            if used:
                rows = [states[i] for i in np.flatnonzero(coefficients[:, j])]
                raise PySindyConversionError(
                    f"from_pysindy: feature {j} '{feature}' (used by {', '.join(rows)}) is not a uavgen "
                    f"term: terms are products of variables, integer powers 1..16 and sin/cos of one "
                    f"variable (FourierLibrary with n_frequencies=1, or CustomLibrary with "
                    f"function_names such as lambda s: f'sin({{s}})'); docs/model-format.md"
                )
            dropped.append(feature)
            continue
        key = _canonical(factors, order)
        if key in column_of_key:
            merged[column_of_key[key]] = merged[column_of_key[key]] + coefficients[:, j]
            continue
        column_of_key[key] = len(library)
        library.append(_term_string(factors, rename))
        merged.append(coefficients[:, j].copy())

    entries = []
    for i, state in enumerate(states):
        for term, column in zip(library, merged):
            c = float(column[i])
            if c != 0.0:
                entries.append({"state": state, "term": term, "coefficient": c + 0.0})

    try:
        import pysindy

        version = getattr(pysindy, "__version__", "unknown")
    except ImportError:  # the model object came from elsewhere (pickled)
        version = "unknown"
    provenance = {
        "tool": TOOL,
        "pysindy_version": version,
        "pysindy_model": kind,
        "feature_library": type(getattr(model, "feature_library", None)).__name__,
        "optimizer": type(getattr(model, "optimizer", None)).__name__,
        "pysindy_variables": variables,
    }
    if dropped:
        provenance["dropped_unused_features"] = dropped
    doc = {
        "format": "uavgen-model/1",
        "kind": "sindy",
        "name": name,
        "states": states,
        "inputs": inputs,
        "provenance": provenance,
        "library": library,
        "kinematic": [],
        "coefficients": entries,
    }
    return json.dumps(doc, indent=2) + "\n"


def from_pysindy(
    model,
    state_names: Optional[Sequence[str]] = None,
    input_names: Optional[Sequence[str]] = None,
    name: str = "pysindy",
):
    """A fitted continuous-time ``pysindy.SINDy`` model (with or without control inputs) as a
    uavgen ``Model`` (module docs): ``Model.f(x, u)`` equals ``model.predict(x, u)``.

    ``state_names`` / ``input_names`` rename the columns of ``x`` / ``u`` (default: the model's
    ``feature_names``, PySINDy's ``x0, x1, …, u0, …`` unless ``fit`` was given ``feature_names``);
    ``name`` is the model's name. Raises ``PySindyConversionError`` (a ``ValueError``) naming the
    feature or name that cannot be converted, and the uavgen model check's error (the same
    message as ``uavgen check``) if the result is not a valid model.
    """
    from . import Model  # the compiled package's class (uavgen/__init__.py)

    text = pysindy_to_model_json(model, state_names=state_names, input_names=input_names, name=name)
    return Model.from_json(text, f"<from_pysindy {name}>")
