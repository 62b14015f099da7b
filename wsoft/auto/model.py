"""The model ``--technique auto`` chooses with: per technique setting (a technique and its
parameters, as a sweep measured it), its frame time and error predicted from a light's features
(:mod:`wsoft.auto.features`).

Two readable predictors, fitted to the same frames (sweep rows joined with their features):

* ``loglinear``: per setting, log frame time and log error as linear functions of a few
  transformed features (:data:`TIME_X`, :data:`ERROR_X`), least squares with a small ridge
  (:data:`RIDGE`) on the standardised features (not on the intercept);
* ``nearest``: per setting, the mean log time and log error of the :data:`K` training frames
  nearest in the standardised features (:data:`NEAREST_X`) that measured it.

The model file (``wsoft/auto/models/<device kind>.json``) holds both, and ``method`` says which
each quantity uses (``wsoft bench auto`` compares them scene by scene held out; ``wsoft
calibrate`` writes the file). ``version`` is :data:`VERSION`; any other is refused with one line
(:class:`~wsoft.errors.ParameterError`). ``scale``: a factor every predicted time is multiplied by
(1 on the device the rows were measured on; a quick calibration measures it elsewhere).

Errors are what the sweep ranks a frame by: penumbra MAE, or the MAE over every covered pixel for
a light whose reference has no penumbra (a point light), as ``wsoft bench pareto`` does. ``flip``
is the pareto rows' mean ꟻLIP of the frame (``error["flip"]``), fitted as the error is (log-linear
on :data:`ERROR_X`, or nearest scenes).

Flicker is a property of a sequence, not of a frame: ``flicker`` in the model file is a second
model of the same format (quantities ``time`` and ``flicker``, :data:`FLICKER_X`), fitted to the
rows of ``wsoft bench temporal`` (:func:`temporal_frames`: per moving sequence, its first frame's
features, each setting's frame time and flicker). Its settings are the only candidates for a
flicker target; a technique without flicker rows is not one.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from wsoft.errors import ParameterError

VERSION = 2
MODELS = Path(__file__).parent / "models"
RIDGE = 1.0
K = 3
MARGIN = 1.0  # the chooser's bounds: prediction x exp(MARGIN x the setting's residual spread), time and error
ERROR_FLOOR = 1e-4  # errors below it are fitted as it (log of 0)
TIME_X = ("log_tris", "covered", "log_pen")
ERROR_X = ("log_pen", "shadowed", "log_depth", "cutout", "point")
FLICKER_X = ("log_pen", "shadowed")
NEAREST_X = ("log_tris", "covered", "log_pen", "shadowed", "log_depth", "cutout", "point")
ALL_X = tuple(dict.fromkeys(TIME_X + ERROR_X + NEAREST_X))
METHODS = ("loglinear", "nearest")
FRAME_QUANTITIES = ("time", "error", "flip")  # the main model's (pareto rows')
SEQUENCE_QUANTITIES = ("time", "flicker")  # the flicker model's (temporal rows')
X_OF = {"time": TIME_X, "error": ERROR_X, "flip": ERROR_X, "flicker": FLICKER_X}
FLOORS = {"time": ERROR_FLOOR, "error": ERROR_FLOOR, "flip": ERROR_FLOOR, "flicker": 1e-5}  # values below are fitted as these (log of 0)
NAMES = {"time": "frame time", "error": "penumbra MAE", "flip": "ꟻLIP", "flicker": "flicker"}


def measured(setting: dict, q: str) -> float | None:
    """A training frame's measured ``q`` of a setting (``time``: its ms), or None where the row has none."""
    v = setting.get("ms" if q == "time" else q)
    return None if v is None else float(v)


def transformed(features: dict) -> dict[str, float]:
    """The features the fits read, from :func:`~wsoft.auto.features.light_features`'s."""
    return {"log_tris": math.log1p(features["triangles_in_view"]), "covered": features["covered_pixels"] / max(features["pixels"], 1.0),
            "log_pen": math.log1p(features["penumbra_px"]), "shadowed": float(features["shadowed_fraction"]),
            "log_depth": math.log(min(max(features["depth_ratio"], 1.0), 1e3)), "cutout": float(features["cutout_triangles"] > 0),
            "point": float(features["light_size"] == 0.0)}


def setting_key(technique: str, params: dict) -> str:
    """One setting's name in the model: ``technique`` and its parameters (sorted JSON)."""
    return technique + json.dumps(params, sort_keys=True)


def row_metric(row: dict) -> str:
    """``mae_penumbra``, or ``mae`` where no entry's reference has a penumbra pixel (a point light)."""
    return "mae_penumbra" if any(e["error"]["penumbra_pixels"] > 0 for e in row["entries"]) else "mae"


def training_frames(rows: list[dict], features: list[dict]) -> list[dict]:
    """Sweep rows (``wsoft bench pareto``'s) joined with their features (rows of ``wsoft bench
    auto``: ``scene``, ``light``, ``features``) by scene and light: per frame the transformed features
    and, per setting, its measured time (ms) and error. Rows without features are left out."""
    feats = {(f["scene"], f["light"]): f["features"] for f in features if "features" in f and f.get("source") != "temporal"}
    out = []
    for r in rows:
        f = feats.get((r["scene"], r["light"]))
        if f is None:
            continue
        metric = row_metric(r)
        settings = {}
        for e in r["entries"]:
            flip = e["error"].get("flip")
            settings[setting_key(e["technique"], e["params"])] = {"technique": e["technique"], "params": e["params"],
                                                                 "ms": float(e["frame_ms"]), "error": float(e["error"][metric]),
                                                                 "flip": None if flip is None else float(flip)}
        out.append({"scene": r["scene"], "light": r["light"], "device": r.get("device", "cpu"), "features": f, "x": transformed(f),
                    "metric": metric, "settings": settings})
    return out


def merge_rows(rows: list[dict], extra: list[dict]) -> tuple[list[dict], int]:
    """``rows`` (pareto's) with the entries of ``extra`` (``wsoft bench modern``'s, the same frames
    measured again) added to the row of the same scene, light and size where that row lacks their
    setting; (the rows, how many entries were added). Rows of ``extra`` without such a row are left out."""
    out, added = [dict(r, entries=list(r["entries"])) for r in rows], 0
    by = {(r["scene"], r["light"], r.get("width"), r.get("height")): r for r in out}
    for x in extra:
        r = by.get((x["scene"], x["light"], x.get("width"), x.get("height")))
        if r is None:
            continue
        have = {setting_key(e["technique"], e["params"]) for e in r["entries"]}
        for e in x["entries"]:
            if setting_key(e["technique"], e["params"]) not in have and "frame_ms" in e and "error" in e:
                r["entries"].append(e)
                added += 1
    return out, added


def temporal_frames(rows: list[dict], features: list[dict]) -> list[dict]:
    """``wsoft bench temporal``'s rows joined with their first frame's features (rows of ``wsoft bench
    auto`` with ``source: temporal``): per moving sequence, each setting's frame time (median over the
    frames), flicker, mean penumbra MAE and ꟻLIP. A still sequence (``static``) is left out: the
    features of one frame cannot tell it from a moving one, and its flicker is only the stochastic
    techniques' crawl (0 for every other), which would pull every prediction towards 0."""
    feats = {(f["scene"], f["light"]): f["features"] for f in features if "features" in f and f.get("source") == "temporal"}
    out = []
    for r in rows:
        f = feats.get((r["scene"], r["light"]))
        if f is None or r.get("static"):
            continue
        settings = {}
        for e in r["entries"]:
            tm = e.get("temporal") or {}
            if tm.get("flicker") is None:
                continue
            settings[setting_key(e["technique"], e["params"])] = {"technique": e["technique"], "params": e["params"], "ms": float(e["frame_ms"]),
                                                                 "flicker": float(tm["flicker"]), "error": tm.get("mae_penumbra"), "flip": e.get("flip")}
        out.append({"scene": r["scene"], "light": r["light"], "device": r.get("device", "cpu"), "features": f, "x": transformed(f),
                    "metric": "flicker", "settings": settings})
    return out


def _ridge(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    A = X.T @ X + RIDGE * np.diag([0.0] + [1.0] * (X.shape[1] - 1))
    return np.linalg.solve(A + 1e-9 * np.eye(len(A)), X.T @ y)


class Model:
    """Predicted time and error per setting; see the module's docstring."""

    def __init__(self, data: dict):
        self.data = data
        self.mean = np.array(data["standardise"]["mean"])
        self.std = np.array(data["standardise"]["std"])

    # -- the file --------------------------------------------------------------------------------
    @classmethod
    def load(cls, path) -> "Model":
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise ParameterError(f"auto model {path}: cannot be read: {exc}") from None
        if not isinstance(data, dict) or data.get("version") != VERSION:
            got = data.get("version") if isinstance(data, dict) else None
            raise ParameterError(f"auto model {path}: version {got!r}, this wsoft reads version {VERSION} (rebuild it: wsoft calibrate)")
        for k in ("device_kind", "method", "settings", "frames", "standardise"):
            if k not in data:
                raise ParameterError(f"auto model {path}: no {k!r}")
        m = cls(data)
        m.path = str(path)
        return m

    def save(self, path) -> None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(self.data, sort_keys=True, separators=(",", ":")) + "\n")

    @property
    def device_kind(self) -> str:
        return self.data["device_kind"]

    @property
    def method(self) -> dict:
        return self.data["method"]

    @property
    def quantities(self) -> tuple:
        return tuple(self.data.get("quantities", ("time", "error")))

    @property
    def scale(self) -> float:
        return float(self.data.get("scale", 1.0))

    def scaled(self, factor: float) -> "Model":
        """The same model with every predicted time multiplied by ``factor`` (more), its flicker model's too."""
        data = dict(self.data, scale=self.scale * float(factor))
        if data.get("flicker"):
            data["flicker"] = dict(data["flicker"], scale=float(data["flicker"].get("scale", 1.0)) * float(factor))
        m = Model(data)
        m.path = getattr(self, "path", None)
        return m

    @property
    def flicker(self) -> "Model | None":
        """The flicker model (temporal rows'), or None where the file has none."""
        d = self.data.get("flicker")
        if not d:
            return None
        m = Model(d)
        m.path = getattr(self, "path", None)
        return m

    def settings(self, quantity: str | None = None) -> dict[str, dict]:
        """Setting key -> ``{"technique", "params"}`` of every setting the model predicts (``quantity``: that it predicts it for)."""
        return {k: {"technique": s["technique"], "params": s["params"]} for k, s in self.data["settings"].items()
                if quantity is None or f"{quantity}_coef" in s}

    # -- predictions -------------------------------------------------------------------------------
    def _z(self, x: dict, names) -> np.ndarray:
        """The standardised features, clamped to the training frames' range (no extrapolation)."""
        idx = [ALL_X.index(n) for n in names]
        v = np.array([x[n] for n in names])
        st = self.data["standardise"]
        lo, hi = np.array(st.get("min", [-np.inf] * len(ALL_X)))[idx], np.array(st.get("max", [np.inf] * len(ALL_X)))[idx]
        return (np.clip(v, lo, hi) - self.mean[idx]) / self.std[idx]

    @property
    def pixels(self) -> float:
        """The training frames' pixels (median): a frame of other size scales its time by (its pixels / these) ** pixel_exponent."""
        return float(self.data.get("pixels", 0.0))

    @property
    def pixel_exponent(self) -> float:
        return float(self.data.get("pixel_exponent", 1.0))

    def predict_q(self, features: dict, key: str, q: str, method: dict | None = None) -> float:
        """Setting ``key``'s predicted ``q`` (``time``: frame ms, scaled to the frame's pixels and by :attr:`scale`)."""
        method = method or self.method
        s = self.data["settings"][key]
        x = transformed(features)
        if method.get(q, "loglinear") == "loglinear":
            c = np.array(s[f"{q}_coef"])
            y = float(c[0] + c[1:] @ self._z(x, X_OF[q]))
        else:
            y = self._nearest(x, key, q)
        v = math.exp(y)
        if q == "time":
            size = (features["pixels"] / self.pixels) ** self.pixel_exponent if self.pixels > 0 else 1.0
            v *= self.scale * size
        return v

    def predict(self, features: dict, key: str, method: dict | None = None) -> tuple[float, float]:
        """(frame ms, error) of setting ``key`` on a light with ``features`` (``method``: per
        quantity, ``loglinear`` or ``nearest``; default the model's own). The flicker model's
        ``error`` is its flicker."""
        return self.predict_q(features, key, "time", method), self.predict_q(features, key, self.quantities[1], method)

    def bounds(self, features: dict, key: str, method: dict | None = None, margin: float | None = None,
               quantity: str | None = None) -> tuple[float, float, float, float]:
        """(ms, value, ms bound, value bound) of ``quantity`` (default the error, the flicker model's
        flicker): the predictions and the same times ``exp(margin x spread)``, the setting's residual
        spread of the log in the fit (what the chooser compares with a budget and a target)."""
        q = quantity or self.quantities[1]
        t, v = self.predict_q(features, key, "time", method), self.predict_q(features, key, q, method)
        s = self.data["settings"][key]
        z = self.margin if margin is None else margin
        return t, v, t * math.exp(z * s["time_spread"]), v * math.exp(z * s[f"{q}_spread"])

    @property
    def margin(self) -> float:
        return float(self.data.get("margin", MARGIN))

    def _nearest(self, x: dict, key: str, q: str) -> float:
        if self.data["frames"] and "values" not in self.data["frames"][0]:
            raise ParameterError("this auto model keeps no training frames' values (its method is log-linear): refit it to predict by nearest scenes")
        z = self._z(x, NEAREST_X)
        cands = [(float(np.sum((np.array(f["z"]) - z) ** 2)), f["values"][key][q])
                 for f in self.data["frames"] if q in f["values"].get(key, {})]
        cands.sort(key=lambda c: c[0])
        return float(np.mean([v for _, v in cands[:K]]))


def fit(frames: list[dict], *, device_kind: str = "cpu", method: dict | None = None, source: dict | None = None,
        margin: float = MARGIN, pixel_exponent: float = 1.0, quantities: tuple = FRAME_QUANTITIES) -> Model:
    """A :class:`Model` fitted to ``frames`` (:func:`training_frames`, or :func:`temporal_frames`
    with ``quantities`` :data:`SEQUENCE_QUANTITIES`). ``method``: per quantity the predictor the
    model uses (default log-linear for each). ``pixel_exponent``: how frame time grows with the
    frame's pixels, (pixels / the training frames') ** it (:func:`wsoft.auto.calibrate.pixel_exponent`
    measures it). A setting's quantity is fitted to the frames that measured it (none: not fitted)."""
    if not frames:
        raise ParameterError("no training frames: the sweep rows have no features (run wsoft bench auto)")
    X = np.array([[f["x"][n] for n in ALL_X] for f in frames])
    mean, std = X.mean(axis=0), X.std(axis=0)
    std = np.where(std > 1e-9, std, 1.0)
    method = {q: (method or {}).get(q, "loglinear") for q in quantities}
    data = {"version": VERSION, "device_kind": device_kind, "method": method, "quantities": list(quantities),
            "scale": 1.0, "source": source or {}, "features": {**{q: list(X_OF[q]) for q in quantities}, "nearest": list(NEAREST_X)},
            "standardise": {"names": list(ALL_X), "mean": mean.tolist(), "std": std.tolist(), "min": X.min(axis=0).tolist(),
                            "max": X.max(axis=0).tolist()},
            "pixels": float(np.median([f["features"]["pixels"] for f in frames])), "pixel_exponent": pixel_exponent, "ridge": RIDGE, "k": K, "margin": margin,
            "settings": {}, "frames": []}
    m = Model(data)
    keys = sorted({k for f in frames for k in f["settings"]})
    for key in keys:
        have = [f for f in frames if key in f["settings"]]
        s0 = have[0]["settings"][key]
        entry = {"technique": s0["technique"], "params": s0["params"], "n": len(have)}
        for q in quantities:
            use = [f for f in have if measured(f["settings"][key], q) is not None]
            if not use:
                continue
            Z = np.array([[1.0, *m._z(f["x"], X_OF[q])] for f in use])
            y = np.array([math.log(max(measured(f["settings"][key], q), FLOORS[q])) for f in use])
            coef = _ridge(Z, y)
            entry[f"{q}_coef"] = [round(float(c), 6) for c in coef]
            # spread of the log residuals, widened for the coefficients fitted (at least 0.1: ~10%)
            dof = max(len(use) - Z.shape[1], 1)
            entry[f"{q}_spread"] = round(max(float(np.sqrt(np.sum((Z @ coef - y) ** 2) / dof)), 0.1), 6)
        data["settings"][key] = entry
    nearest = "nearest" in method.values()  # the frames' values only where a predictor reads them
    for f in frames:
        data["frames"].append({"scene": f["scene"], "light": f["light"], "z": [round(float(v), 6) for v in m._z(f["x"], NEAREST_X)]})
        if nearest:
            data["frames"][-1]["values"] = {k: {q: round(math.log(max(measured(s, q), FLOORS[q])), 4) for q in quantities if measured(s, q) is not None}
                                            for k, s in f["settings"].items()}
    return m


def model_path(device_kind: str) -> Path:
    return MODELS / f"{device_kind}.json"


def device_kind(device: str) -> str:
    """The model's device kind of a Warp device name: ``cpu`` or ``cuda``."""
    return "cpu" if str(device).startswith("cpu") else "cuda"


def load_model(path=None, device: str = "cpu") -> tuple[Model, str]:
    """The model for ``device`` and a note ('' when it is the device's own): ``path`` when given,
    else the package's model of the device's kind, else the CPU model (the note says so; the
    chooser scales it by a quick calibration, :func:`wsoft.auto.calibrate.quick_scale`)."""
    if path is not None:
        return Model.load(path), ""
    kind = device_kind(device)
    p = model_path(kind)
    if p.is_file():
        return Model.load(p), ""
    return Model.load(model_path("cpu")), f"no auto model for device kind {kind!r}: the CPU model is used, its times scaled by a quick calibration"


def setting_text(technique: str, params: dict) -> str:
    """``pcss(filter_samples=100, shadow_map_size=2048)``."""
    return technique + ("(" + ", ".join(f"{k}={v}" for k, v in sorted(params.items())) + ")" if params else "")


GOALS = ("budget_ms", "target_error", "target_flip", "target_flicker")
GOAL_QUANTITY = {"budget_ms": "error", "target_error": "error", "target_flip": "flip", "target_flicker": "flicker"}
GOAL_OPTION = {"budget_ms": "--budget-ms", "target_error": "--target-error", "target_flip": "--target-flip", "target_flicker": "--target-flicker"}


def goal_of(**goals) -> tuple[str, float]:
    """The one goal given (name in :data:`GOALS`, value); a one-line error for none, two, or a value
    that is not a positive finite number."""
    given = {k: v for k, v in goals.items() if v is not None}
    for k, v in given.items():
        if k not in GOALS:
            raise ParameterError(f"auto: unknown goal {k!r} (one of {', '.join(GOALS)})")
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
            raise ParameterError(f"auto: {k} ({GOAL_OPTION[k]}) must be a positive finite number, got {v!r}")
    if len(given) != 1:
        raise ParameterError("auto: give one goal: a time budget (budget_ms / --budget-ms) or a target of penumbra MAE (target_error / "
                             "--target-error), ꟻLIP (target_flip / --target-flip) or flicker (target_flicker / --target-flicker)"
                             + (f", not {len(given)}" if given else ""))
    return next(iter(given.items()))


def pick(preds: dict[str, tuple], *, budget_ms: float | None = None, target_error: float | None = None, target_flip: float | None = None,
         target_flicker: float | None = None) -> tuple[str, str | None, str]:
    """(choice, runner-up or None, warning or '') among ``preds`` (key -> predicted (ms, value), or
    (ms, value, ms bound, value bound) as :meth:`~wsoft.auto.model.Model.bounds` gives, the value
    being the goal's quantity: the error for a budget or an error target, ꟻLIP or flicker for
    theirs: a budget is compared with the time bound, a target with the value's bound), ordered
    deterministically (ties broken by the key)."""
    preds = {k: (v[2], v[3]) if len(v) == 4 else (v[0], v[1]) for k, v in preds.items()}
    goal, value = goal_of(budget_ms=budget_ms, target_error=target_error, target_flip=target_flip, target_flicker=target_flicker)
    if not preds:
        raise ParameterError("auto: no candidate setting for this light")
    if goal == "budget_ms":
        ok = sorted((k for k, (t, _) in preds.items() if t <= value), key=lambda k: (preds[k][1], preds[k][0], k))
        if ok:
            return ok[0], (ok[1] if len(ok) > 1 else None), ""
        order = sorted(preds, key=lambda k: (preds[k][0], k))
        t = preds[order[0]][0]
        return order[0], (order[1] if len(order) > 1 else None), (
            f"budget {value:g} ms is below every candidate's predicted time (its bound: the prediction and its spread): the cheapest, "
            f"rendered, is bounded at {t:.1f} ms, {t - value:.1f} ms ({100 * (t / value - 1):.0f}%) over it")
    name = {"target_error": "error", "target_flip": "ꟻLIP", "target_flicker": "flicker"}[goal]
    ok = sorted((k for k, (_, e) in preds.items() if e <= value), key=lambda k: (preds[k][0], preds[k][1], k))
    if ok:
        return ok[0], (ok[1] if len(ok) > 1 else None), ""
    order = sorted(preds, key=lambda k: (preds[k][1], preds[k][0], k))
    e = preds[order[0]][1]
    return order[0], (order[1] if len(order) > 1 else None), (
        f"{name} target {value:g} is below every candidate's predicted {name} (its bound): the most accurate, rendered, is "
        f"bounded at {e:.4f}")
