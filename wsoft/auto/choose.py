"""Choosing, per light, the technique setting predicted to meet a time budget or an error target.

:func:`pick` ranks candidates' predictions: with a budget, the lowest predicted error among those
predicted to fit it (ties: the faster), else the cheapest with a warning saying by how much the
budget is exceeded; with a target (penumbra MAE, ꟻLIP or flicker), the fastest predicted to reach
it, else the most accurate with a warning. :func:`choose` does it for one light of a stage: its features
(:func:`~wsoft.auto.features.light_features`), every setting of the model whose technique is
registered and ``supports`` the light (plugins included, once the model has rows for them),
their predictions (:class:`~wsoft.auto.model.Model`). A flicker target's candidates are the
settings of the model's flicker model (fitted to ``wsoft bench temporal``'s rows): a technique
without flicker rows is not one, and the record says so (``not_candidates``); likewise for a ꟻLIP
target, a setting without ꟻLIP in its rows. :class:`AutoTechnique` is what
``render(scene, "auto", budget_ms=...)`` builds: each light's passes are its choice's.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from wsoft.auto.model import GOAL_QUANTITY, goal_of, pick, setting_text
from wsoft.errors import ParameterError
from wsoft.params import param

__all__ = ["AutoParams", "AutoWarning", "Choice", "auto_technique", "candidates", "choose", "pick", "setting_text"]


class AutoWarning(UserWarning):
    """A light ``auto`` cannot serve as asked (no candidate fits the budget or reaches the target),
    or a model used on a device kind it was not fitted for."""


@dataclass
class Choice:
    """What ``auto`` chose for one light, and from what: the record ``wsoft plan`` prints and a frame's stats keep."""

    light: str
    goal: dict
    features: dict
    candidates: list[dict]  # technique, params, setting, predicted_ms and ms_bound, predicted_/_bound of error, flip, flicker (None: not predicted)
    choice: dict
    runner_up: dict | None
    warning: str
    model: dict
    not_candidates: dict | None = None  # technique -> why it is not a candidate for this goal (no flicker or ꟻLIP rows)

    def record(self) -> dict:
        return {"light": self.light, "goal": self.goal, "features": self.features, "choice": self.choice, "runner_up": self.runner_up,
                "warning": self.warning, "model": self.model, "candidates": self.candidates, "not_candidates": self.not_candidates or {}}


def candidates(model, scene, light, *, width: int | None = None, height: int | None = None, camera=None, quantity: str | None = None,
               _ok: dict | None = None) -> dict[str, dict]:
    """The model's settings whose technique is registered and renders ``light`` in this frame
    (:func:`~wsoft.pipeline.build.refusal`: it supports the light, and needs no cube map it cannot
    use) (key -> technique, params); ``quantity``: only the settings the model predicts it for."""
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES

    out, ok = {}, ({} if _ok is None else _ok)
    for key, s in model.settings(quantity).items():
        name = s["technique"]
        if name not in TECHNIQUES:
            continue
        if name not in ok:
            ok[name] = refusal(name, scene, light, width=width, height=height, camera=camera) is None
        if ok[name]:
            try:
                TECHNIQUES[name].make_params(s["params"])
            except ParameterError:  # a setting of a technique whose parameters changed since the rows
                continue
            out[key] = s
    return out


def choose(scene, light, *, budget_ms: float | None = None, target_error: float | None = None, target_flip: float | None = None,
           target_flicker: float | None = None, model=None, model_note: str = "", width: int | None = None, height: int | None = None,
           camera=None, device: str = "cpu", features: dict | None = None) -> Choice:
    """The :class:`Choice` for ``light`` of ``scene`` (see the module's docstring)."""
    from wsoft.auto.features import light_features
    from wsoft.auto.model import load_model

    goal, value = goal_of(budget_ms=budget_ms, target_error=target_error, target_flip=target_flip, target_flicker=target_flicker)
    q = GOAL_QUANTITY[goal]
    if model is None:
        model, model_note = load_model(device=device)
        if model_note:
            from wsoft.auto.calibrate import quick_scale

            model = model.scaled(quick_scale(model, device))
    if not hasattr(light, "kind"):
        light = scene.find_light(str(light))
    where = getattr(model, "path", "given")
    fm = model.flicker
    if goal == "target_flicker" and fm is None:
        raise ParameterError(f"auto: the model ({where}) has no flicker model (wsoft bench temporal's rows): rebuild it with wsoft calibrate --temporal")
    ok: dict = {}
    every = candidates(model, scene, light, width=width, height=height, camera=camera, _ok=ok)
    source = fm if goal == "target_flicker" else model
    cands = candidates(source, scene, light, width=width, height=height, camera=camera, quantity=q, _ok=ok)
    if not cands:
        raise ParameterError(f"auto: no setting of the model ({where}) supports light {light.path}" + ("" if q == "error" else f" with {q} rows"))
    if features is None:
        features = light_features(scene, light, width=width, height=height, camera=camera, device=device)
    rows = {"target_flicker": "flicker rows (wsoft bench temporal)", "target_flip": "ꟻLIP in its rows"}.get(goal)
    missing = {s["technique"] for s in every.values()} - {s["technique"] for s in cands.values()}
    not_cands = {t: f"not a candidate for a {q} target: no {rows}" for t in sorted(missing)} if rows else {}
    preds = {k: source.bounds(features, k, quantity=q) for k in cands}
    key, runner, warning = pick(preds, **{goal: value})
    main = model.data["settings"]
    flick = fm.data["settings"] if fm is not None else {}

    def entry(k):
        s = cands[k]
        out = {"technique": s["technique"], "params": s["params"], "setting": setting_text(s["technique"], s["params"]),
               "predicted_ms": round(preds[k][0], 3), "ms_bound": round(preds[k][2], 3)}
        for qq, m, have in (("error", model, main), ("flip", model, main), ("flicker", fm, flick)):
            if qq == q:
                out[f"predicted_{qq}"], out[f"{qq}_bound"] = round(preds[k][1], 5), round(preds[k][3], 5)
            elif k in have and f"{qq}_coef" in have[k]:
                _, v, _, b = m.bounds(features, k, quantity=qq)
                out[f"predicted_{qq}"], out[f"{qq}_bound"] = round(v, 5), round(b, 5)
            else:
                out[f"predicted_{qq}"] = out[f"{qq}_bound"] = None
        return out

    info = {"path": getattr(model, "path", None), "device_kind": model.device_kind, "method": source.method, "scale": model.scale,
            "note": model_note, "predicts": "flicker model (wsoft bench temporal's rows: time of a sequence's frame)" if source is fm else "frame model"}
    return Choice(light.path, {goal: value}, {k: round(v, 6) for k, v in features.items()},
                  [entry(k) for k in sorted(preds, key=lambda k: (preds[k][0], k))], entry(key), entry(runner) if runner else None,
                  f"auto: light {light.path}: {warning}" if warning else "", info, not_cands)


@dataclass(frozen=True)
class AutoParams:
    budget_ms: float = param(0.0, "frame time budget in ms: per light, the lowest predicted error whose predicted time fits (0: none)",
                             range=(0.0, 1e7))
    target_error: float = param(0.0, "penumbra MAE to reach: per light, the fastest setting predicted to reach it (0: none)", range=(0.0, 1.0))
    target_flip: float = param(0.0, "mean ꟻLIP to reach: per light, the fastest setting predicted to reach it (0: none)", range=(0.0, 1.0))
    target_flicker: float = param(0.0, "flicker to reach over a sequence: per light, the fastest setting with flicker rows predicted to reach it "
                                  "(0: none)", range=(0.0, 1.0))
    model: str = param("", "the model file (default: the package's for the device kind, wsoft/auto/models/)")

    def __post_init__(self):
        from wsoft.params import check_ranges

        check_ranges(self)
        if sum(v > 0 for v in (self.budget_ms, self.target_error, self.target_flip, self.target_flicker)) != 1:
            raise ValueError("give one of budget_ms, target_error, target_flip, target_flicker (a positive number)")


def _auto_class():
    """:class:`AutoTechnique`, defined at first use (its base class imports the technique registry)."""
    global AutoTechnique
    if "AutoTechnique" in globals():
        return AutoTechnique
    from wsoft.techniques.base import PassSpec, Technique

    class AutoTechnique(Technique):
        """``auto``: per light, the registered technique and setting the model predicts meets the
        budget or the target (:func:`choose`); the light's passes are its choice's. Not registered:
        ``render(scene, "auto", budget_ms=...)`` and ``--technique auto`` build it."""

        name = "auto"
        summary = "per light, the technique and setting predicted to meet a time budget or an error target"
        Params = AutoParams
        passes = (PassSpec("choice", (), ("visibility",)),)

        def __init__(self, params):
            super().__init__(params)
            self.choices: dict[str, Choice] = {}
            self._models: dict[str, tuple] = {}  # device -> (model, note)
            self._plain = None

        def _known(self):
            """The model unscaled (which settings it knows, for :meth:`supports`)."""
            if self._plain is None:
                from wsoft.auto.model import load_model

                self._plain = load_model(self.params.model or None)[0]
            return self._plain

        def model(self, device: str):
            """The model for ``device`` (scaled by a quick calibration where it is another kind's, with an :class:`AutoWarning`)."""
            if device not in self._models:
                from wsoft.auto.model import load_model

                m, note = load_model(self.params.model or None, device=device)
                if note:
                    from wsoft.auto.calibrate import quick_scale

                    m = m.scaled(quick_scale(m, device))
                    note = f"{note} (x {m.scale:.3g})"
                    warnings.warn(f"auto: {note}", AutoWarning, stacklevel=2)
                self._models[device] = (m, note)
            return self._models[device][0]

        def supports(self, scene, light) -> str | None:
            from wsoft.techniques import TECHNIQUES, create

            names = sorted({s["technique"] for s in self._known().settings().values()} & set(TECHNIQUES))
            why = [create(n).supports(scene, light) for n in names]
            return None if any(w is None for w in why) else f"no technique of the auto model supports it ({'; '.join(sorted(set(filter(None, why))))})"

        def choose(self, scene, light, *, width, height, camera, device) -> "Choice":
            share = self.params.budget_ms / max(getattr(self, "light_count", 1), 1)
            c = choose(scene, light, budget_ms=share or None, target_error=self.params.target_error or None,
                       target_flip=self.params.target_flip or None, target_flicker=self.params.target_flicker or None, model=self.model(device), model_note=self._models[device][1], width=width, height=height, camera=camera, device=device)
            self.choices[light.path] = c
            return c

        def technique_for(self, ctx, light):
            """The chosen technique instance for ``light`` on the render context ``ctx`` (the build's hook)."""
            from wsoft.techniques import create

            c = self.choose(ctx.scene, light, width=ctx.width, height=ctx.height, camera=ctx.camera, device=ctx.device)
            return create(c.choice["technique"], c.choice["params"]), c

        def add_passes(self, ctx, light):  # pragma: no cover - the build substitutes the choice (technique_for)
            raise NotImplementedError("auto's passes are its choice's")

    return AutoTechnique


def auto_technique(params: dict):
    """An ``auto`` technique instance from ``{budget_ms | target_error | target_flip | target_flicker, model}`` (unknown keys are errors)."""
    cls = _auto_class()
    return cls(cls.make_params(params))
