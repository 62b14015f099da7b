"""Techniques by name: the bundled ones (one module or package each under ``wsoft/techniques/``,
named after the technique) and those other packages declare in the entry-point group
``wsoft.techniques`` (``name = "package.module:Class"``, the class a subclass of
:class:`Technique`). Each technique class declares its own ``name``, parameters, passes, what it
supports and its quality knobs; nothing here lists them.

:data:`NAMES` gives the names without importing anything (the modules' and the entry points'
names: ``wsoft --help`` needs no Warp); ``TECHNIQUES`` (name -> class) imports them at first use.
A plugin that cannot be imported, is not a :class:`Technique`, is named otherwise than its entry
point or takes a bundled technique's name is left out with a one-line :class:`PluginWarning`
naming the entry point; the others keep working. A plugin that draws light maps without the
parameter ``cube`` (its ``Params`` not a :class:`~wsoft.params.LightViewParams`) and without a
``cube_refusal`` is kept with a :class:`PluginWarning` saying what it lacks
(:meth:`Technique.cube_map_problem`). :func:`markdown_table` renders the README's
table from the classes.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import pkgutil
import warnings

from wsoft.errors import ParameterError, suggestion
from wsoft.techniques.base import LIGHT_MAP_KINDS, PassSpec, Quality, Technique, Tolerance

ENTRY_POINT_GROUP = "wsoft.techniques"
_NOT_TECHNIQUES = frozenset({"base"})  # modules of this package that hold no technique
_TECHNIQUES: dict[str, type[Technique]] | None = None
_ENTRY_POINTS: list | None = None  # the plugins' entry points as read from the installed metadata (plugin_entry_points)


class PluginWarning(UserWarning):
    """A technique plugin (entry point of :data:`ENTRY_POINT_GROUP`) that was left out, and why."""


def bundled_names() -> list[str]:
    """The bundled techniques' names: the modules and packages of ``wsoft.techniques`` (not imported)."""
    return list(_bundled())


@functools.cache
def _bundled() -> tuple[str, ...]:
    return tuple(sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_") and m.name not in _NOT_TECHNIQUES))


def plugin_entry_points() -> list:
    """The installed entry points of :data:`ENTRY_POINT_GROUP` (read from the packages' metadata, not
    loaded): read once a process, since every installed distribution's metadata is scanned for them;
    :func:`reload_plugins` reads them again."""
    global _ENTRY_POINTS
    if _ENTRY_POINTS is None:
        from importlib.metadata import entry_points

        _ENTRY_POINTS = sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: ep.name)
    return list(_ENTRY_POINTS)


def names() -> tuple[str, ...]:
    """Every technique's name, bundled first, without importing any technique (a plugin that fails
    to load later is left out of ``TECHNIQUES``, not of this list)."""
    bundled = bundled_names()
    return tuple(bundled + sorted({ep.name for ep in plugin_entry_points()} - set(bundled)))


def _defined_in(module) -> list[type[Technique]]:
    """The technique classes ``module`` (or one of its submodules) defines: Technique subclasses
    that declare a ``name`` of their own."""
    return [c for c in vars(module).values() if isinstance(c, type) and issubclass(c, Technique) and "name" in c.__dict__
            and (c.__module__ == module.__name__ or c.__module__.startswith(module.__name__ + "."))]


def _with_manual(cls: type[Technique]) -> type[Technique]:
    """The class, its docstring (the manual) ending with its parameter table."""
    if "\n\nParameters:\n\n" not in (cls.__doc__ or ""):
        cls.__doc__ = (cls.__doc__ or "").rstrip() + "\n\nParameters:\n\n" + parameter_table(cls) + "\n"
    return cls


def _load_bundled() -> dict[str, type[Technique]]:
    found = {}
    for name in bundled_names():
        module = importlib.import_module(f"{__name__}.{name}")
        classes = _defined_in(module)
        if [c.name for c in classes] != [name]:
            raise RuntimeError(f"{module.__name__} must define one technique named {name!r}, defines {[c.name for c in classes]}")
        why = classes[0].declaration_problem() or classes[0].cube_map_problem()
        if why:
            raise RuntimeError(f"{module.__name__}: {why}")
        found[name] = _with_manual(classes[0])
    return found


def _load_plugins(bundled: dict[str, type[Technique]]) -> dict[str, type[Technique]]:
    found: dict[str, type[Technique]] = {}
    for ep in plugin_entry_points():
        where = f"technique plugin {ep.name} = {ep.value} (entry point group {ENTRY_POINT_GROUP})"
        if ep.name in bundled or ep.name in found:
            warnings.warn(f"{where}: left out, {ep.name!r} is already a {'bundled' if ep.name in bundled else 'plugin'} technique",
                          PluginWarning, stacklevel=3)
            continue
        try:
            cls = ep.load()
        except Exception as exc:  # a plugin's own bug: reported, the others keep working
            warnings.warn(f"{where}: left out, it cannot be imported: {type(exc).__name__}: {' '.join(str(exc).split())}",
                          PluginWarning, stacklevel=3)
            continue
        if not (isinstance(cls, type) and issubclass(cls, Technique)):
            warnings.warn(f"{where}: left out, {cls!r} is not a subclass of wsoft.techniques.Technique", PluginWarning, stacklevel=3)
            continue
        why = cls.declaration_problem()
        if why is None and cls.name != ep.name:
            why = f"its class is named {cls.name!r}, not {ep.name!r}"
        if why:
            warnings.warn(f"{where}: left out, {why}", PluginWarning, stacklevel=3)
            continue
        lacks = cls.cube_map_problem()
        if lacks:  # kept: it renders what one frustum holds, and says so here
            warnings.warn(f"{where}: {lacks}", PluginWarning, stacklevel=3)
        found[ep.name] = _with_manual(cls)
    return found


def _techniques() -> dict[str, type[Technique]]:
    """``TECHNIQUES``, loaded once: the bundled techniques by name, then the plugins."""
    global _TECHNIQUES
    if _TECHNIQUES is None:
        bundled = _load_bundled()
        _TECHNIQUES = {**bundled, **_load_plugins(bundled)}
    return _TECHNIQUES


def reload_plugins() -> dict[str, type[Technique]]:
    """Look up the installed plugins again (after one was installed or removed in a running
    process): ``TECHNIQUES`` (the same dict) then holds the bundled techniques and the plugins this lookup finds."""
    global _ENTRY_POINTS
    techniques = _techniques()
    importlib.invalidate_caches()
    _ENTRY_POINTS = None
    bundled = {n: techniques[n] for n in bundled_names()}
    techniques.clear()
    techniques.update({**bundled, **_load_plugins(bundled)})
    return techniques


def __getattr__(name: str):
    if name == "TECHNIQUES":
        return _techniques()
    if name == "NAMES":
        return names()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def unmapped_techniques() -> list[str]:
    """The registered techniques that draw no light map (none of their passes reads
    :data:`LIGHT_MAP_KINDS`): they shadow receivers in every direction from a light."""
    return sorted(n for n, c in _techniques().items() if not set(c.reads()) & set(LIGHT_MAP_KINDS))


def unknown_technique(name: str, known) -> ParameterError:
    """The one-line error for a technique name that is not one of ``known``: the closest names, then all."""
    return ParameterError(f"unknown technique {name!r}{suggestion(name, known)}; techniques: {', '.join(sorted(known))}")


def check_names(wanted) -> None:
    """Raise :func:`unknown_technique` for the first name of ``wanted`` that no bundled technique or
    installed plugin has, without importing any technique (so without Warp)."""
    known = names()
    for name in wanted:
        if name not in known:
            raise unknown_technique(name, known)


def get_technique(name: str) -> type[Technique]:
    techniques = _techniques()
    try:
        return techniques[name]
    except KeyError:
        raise unknown_technique(name, techniques) from None


def create(name: str, params: dict | None = None) -> Technique:
    """A technique instance from its name and a dict of parameters (unknown keys are errors)."""
    cls = get_technique(name)
    return cls(cls.make_params(params))


def parameter_table(cls: type[Technique]) -> str:
    """The technique's parameters as a markdown table (name, type, default, range, meaning)."""
    rows = ["| parameter | type | default | range | meaning |", "|---|---|---|---|---|"]
    for p in cls.describe()["parameters"]:
        rows.append(f"| `{p['name']}` | {p['type']} | {p['default']!r} | {p['range']} | {p['meaning']} |")
    return "\n".join(rows)


def markdown_table(techniques: dict[str, type[Technique]] | None = None) -> str:
    """The README's technique table, from the code: name, summary, parameters with defaults, quality
    knobs (``techniques``: default the bundled ones, the README's own)."""
    if techniques is None:
        bundled = set(bundled_names())
        techniques = {n: c for n, c in _techniques().items() if n in bundled}
    rows = ["| name | what | parameters (default) | quality knobs (sweep values) |", "|---|---|---|---|"]
    for name in ["reference"] * ("reference" in techniques) + sorted(n for n in techniques if n != "reference"):
        cls = techniques[name]
        params = ", ".join(f"`{f.name}` ({f.default!r})" for f in dataclasses.fields(cls.Params))
        quality = "; ".join(f"`{q.param}`: {', '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in q.values)}" for q in cls.quality) or "-"
        rows.append(f"| `{name}` | {cls.summary} | {params} | {quality} |")
    return "\n".join(rows)


__all__ = ["ENTRY_POINT_GROUP", "LIGHT_MAP_KINDS", "NAMES", "PassSpec", "PluginWarning", "TECHNIQUES", "Quality", "Technique", "Tolerance", "bundled_names",
           "check_names", "create", "get_technique", "markdown_table", "names", "parameter_table", "plugin_entry_points", "reload_plugins",
           "unmapped_techniques"]
