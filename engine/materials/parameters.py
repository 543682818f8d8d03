"""Declared parameters of the material models: one table per model, one reader for everyone.

Each model file ends with a ``DECLARATION = ModelDeclaration(...)``: its parameters with units,
allowed ranges, defaults, kinds, whether they may vary over a surface (``texturable``) and the
Polarising BSDF node socket that shows them in Blender.  From these tables come

- the scene loader's material parsing (JSON keys, defaults, ranges, allowed keys),
- the flat ``NAME=VALUE`` catalogue of ``python -m engine mueller`` and its help text,
- the Blender node's sockets and the exporter's reads of them.

Values are read through :class:`Values`, which gives every user mistake the same message:
``SceneError("<field>.<name>", "must be a finite number in [lo, hi], got …")``; this is where a value is
range-checked (once: the constructors keep only cheap guards for direct use).  Rules that tie
parameters together (metal vs n/k, …) are small builder functions next to each declaration
(``@DECLARATION.builder``); they take their ranges and messages from here, and every microfacet
roughness its smooth limit and least slope from engine.materials.roughness (``declared_slope``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..spectral import ConstantSpectrum, Spectrum, named_ior, parse_spectrum
from ..textures import TexturedNumber, TexturedSpectrum, TextureInput, parse_texture_input


class _Required:
    def __repr__(self):
        return "REQUIRED"


#: Default of a parameter that must be given.
REQUIRED = _Required()

#: Kinds of parameters: a real number, a spectrum (number, [r, g, b] or a table), one of a few
#: words, a named measured metal (spectral n, κ), a direction (3-vector), another material, a list
#: of coats, a list of materials, a list of numbers (each read as the parameter's ``element``).
#: Materials and coats are assembled by the callers (scene files nest them, the catalogue
#: flattens them).
KINDS = ("number", "spectrum", "choice", "metal", "direction", "material", "coats", "materials", "numbers",
         "bool")
#: A switch (kind "bool"): JSON true/false; where values are text (``python -m engine mueller --param``)
#: also these words.
_BOOL_WORDS = {"true": True, "1": True, "yes": True, "on": True, "false": False, "0": False, "no": False,
               "off": False}
SOCKET_TYPES = ("FLOAT", "COLOR", "SHADER")
#: Wavelengths over which a spectrum's values are checked against the declared range (nm).
_CHECK_NM = np.linspace(360.0, 830.0, 95)


@dataclass(frozen=True)
class Socket:
    """A Polarising BSDF node input: name (saved .blend files refer to it), Blender socket type
    (FLOAT, COLOR, SHADER), default, the UI's min/max and tooltip."""

    name: str
    type: str
    default: object
    soft_min: float | None
    soft_max: float | None
    description: str

    def as_tuple(self) -> tuple:
        return (self.name, self.type, self.default, self.soft_min, self.soft_max, self.description)


@dataclass(frozen=True)
class Parameter:
    """One parameter of a material model.

    ``lo``/``hi`` (with open ends where ``lo_open``/``hi_open``) bound numbers and every value of a
    spectrum; ``spectrum`` is the spectrum kind of engine.spectral.parse_spectrum ("reflectance"
    or "unbounded"); ``only_with = (other, values)`` makes the parameter meaningful (and, when
    REQUIRED, needed) only where parameter ``other`` has one of ``values``.
    """

    name: str
    doc: str
    kind: str = "number"
    unit: str = ""
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    default: object = REQUIRED
    spectrum: str = "unbounded"
    choices: tuple = ()
    texturable: bool = False
    only_with: tuple | None = None
    socket: Socket | None = None
    members: ModelDeclaration | None = None    # kind "coats": the declaration of one element
    #: kind "numbers": one element of the list (its range, unit and whether it may be a texture); the
    #: list itself is never a texture object, so the list parameter is not ``texturable``
    element: Parameter | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"parameter {self.name}: kind must be one of {KINDS}, got {self.kind!r}")
        if (self.kind == "numbers") != (self.element is not None):
            raise ValueError(f"parameter {self.name}: a list of numbers (and only it) needs an element declaration")
        if self.kind == "numbers" and (self.element.kind != "number" or self.texturable):
            raise ValueError(f"parameter {self.name}: the elements of a list of numbers are numbers (mark the "
                             "element texturable, not the list)")
        if self.socket is not None and self.socket.type not in SOCKET_TYPES:
            raise ValueError(f"parameter {self.name}: socket type must be one of {SOCKET_TYPES}")

    def with_(self, **changes) -> Parameter:
        """A copy with some fields changed (e.g. another model's socket default)."""
        return dataclasses.replace(self, **changes)

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def range_text(self) -> str:
        """The allowed interval as messages print it, e.g. ``(0, 100]``."""
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"

    def contains(self, v: float) -> bool:
        return (math.isfinite(v) and self.lo <= v <= self.hi and not (self.lo_open and v == self.lo)
                and not (self.hi_open and v == self.hi))

    def allowed_text(self) -> str:
        """What a valid value looks like, for help texts and 'is required' messages."""
        if self.kind in ("number", "spectrum"):
            what = "a number" if self.kind == "number" else "a spectrum"
            return f"{what} in {self.range_text()}" + (f" {self.unit}" if self.unit else "")
        if self.kind == "choice":
            return "one of " + ", ".join(map(repr, self.choices))
        if self.kind == "numbers":
            return f"a list, each {self.element.allowed_text()}" + (" or a texture" if self.element.texturable else "")
        return {"bool": "true or false", "metal": "a measured metal name", "direction": "a list of 3 numbers",
                "material": "a material", "coats": "a list of coats",
                "materials": "a list of materials (inline or by name)"}[self.kind]

    def help_text(self, prefix: str = "") -> str:
        """One line for help listings: doc, allowed values, default (``prefix``: of flat names)."""
        if self.required and self.only_with is not None:
            other, allowed = self.only_with
            default = f"required with {prefix}{other}={'|'.join(allowed)}"
        else:
            default = "required" if self.required else "optional" if self.default is None else \
                f"default {self.default!r}"
        if self.kind == "choice":
            return f"{self.doc}: {' | '.join(c for c in self.choices)} ({default})"
        return f"{self.doc}; {self.allowed_text()} ({default})"

    # ------------------------------------------------------------------ checking one value

    def number(self, raw, field: str, text: bool = False) -> float:
        """A finite number within the declared range (``text``: numeric strings are accepted)."""
        value = raw
        if text and isinstance(raw, str):
            try:
                value = float(raw)
            except ValueError:
                raise SceneError(field, f"must be a number, got {raw!r}") from None
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise SceneError(field, f"must be a number, got {raw!r}")
        v = float(value)
        if not self.contains(v):
            raise SceneError(field, f"must be a finite number in {self.range_text()}, got {raw!r}")
        return v

    def read(self, raw, field: str, text: bool = False, base_dir: str | None = None):
        """The validated value of ``raw`` (a JSON value, or a string where ``text``).

        A texturable number or spectrum may be a texture object (engine.textures.inputs, image
        paths relative to ``base_dir``): the value is then a TexturedNumber / TexturedSpectrum
        whose every possible value lies in the declared range.
        """
        if is_texture_object(raw) and self.kind in ("number", "spectrum"):
            return self.read_texture(raw, field, base_dir)
        if self.kind == "number" and isinstance(raw, TexturedNumber):     # built in code (a composite model)
            if not self.texturable:
                raise SceneError(field, f"cannot vary over the surface: give a constant ({self.allowed_text()})")
            if not (self.contains(raw.lo) and self.contains(raw.hi)):
                raise SceneError(field, f"texture values span [{raw.lo:g}, {raw.hi:g}]: must be in {self.range_text()}")
            return raw
        if self.kind == "number":
            return self.number(raw, field, text)
        if self.kind == "spectrum":
            if isinstance(raw, TexturedSpectrum):       # built in code (the Blender exporter)
                if not self.texturable:
                    raise SceneError(field, f"cannot vary over the surface: give a constant ({self.allowed_text()})")
                if not (self.contains(raw.lo) and self.contains(raw.hi)):
                    raise SceneError(field, f"texture values span [{raw.lo:g}, {raw.hi:g}]: must be in "
                                            f"{self.range_text()}")
                return raw
            if isinstance(raw, Spectrum):               # built in code (the Blender exporter)
                self.check_spectrum(raw, field)
                return raw
            if text:
                return ConstantSpectrum(self.number(raw, field, text))
            spec = parse_spectrum(raw, field, kind=self.spectrum)
            self.check_spectrum(spec, field)
            return spec
        if self.kind == "numbers":
            if not isinstance(raw, (list, tuple)):
                raise SceneError(field, f"must be a list, each {self.element.allowed_text()}, got {raw!r}")
            return [self.element.read(x, f"{field}[{i}]", text, base_dir) for i, x in enumerate(raw)]
        if self.kind == "choice":
            if raw not in self.choices:
                raise SceneError(field, f"must be one of {', '.join(map(repr, self.choices))}, got {raw!r}")
            return raw
        if self.kind == "bool":
            if text and isinstance(raw, str) and raw.strip().lower() in _BOOL_WORDS:
                return _BOOL_WORDS[raw.strip().lower()]
            if not isinstance(raw, (bool, np.bool_)):
                raise SceneError(field, f"must be true or false, got {raw!r}")
            return bool(raw)
        if self.kind == "metal":
            return named_ior(raw, field=field)
        if self.kind == "direction":
            return _direction(raw, field)
        return raw      # materials and coats: assembled by the caller

    def read_texture(self, raw, field: str, base_dir: str | None):
        """A texture object (or an engine.textures.TextureInput built in code, e.g. by the Blender
        exporter from an image in memory) as this parameter's value (see ``read``)."""
        if not self.texturable:
            raise SceneError(field, "cannot vary over the surface: give a constant "
                                    f"({self.allowed_text()})")
        source = raw if isinstance(raw, TextureInput) else parse_texture_input(raw, field, base_dir)
        value = TexturedSpectrum(source, self.spectrum) if self.kind == "spectrum" else TexturedNumber(source)
        value = value.clamped_to(-math.inf if self.lo_open else self.lo, math.inf if self.hi_open else self.hi)
        if not (self.contains(value.lo) and self.contains(value.hi)):
            raise SceneError(field, f"texture values (after scale and offset) span [{value.lo:g}, {value.hi:g}]: "
                                    f"must be in {self.range_text()}" + (f" {self.unit}" if self.unit else ""))
        return value

    def check_spectrum(self, spec, field: str):
        """Every value of ``spec`` over 360–830 nm within the declared range."""
        v = np.asarray(spec.eval(_CHECK_NM), dtype=np.float64)
        ok = np.isfinite(v) & (v >= self.lo) & (v <= self.hi)
        if self.lo_open:
            ok &= v > self.lo
        if self.hi_open:
            ok &= v < self.hi
        if not np.all(ok):
            if self.hi == math.inf:
                words = f"{'>' if self.lo_open else '≥'} {self.lo:g}"
            else:
                words = f"in {self.range_text()}"
            raise SceneError(field, f"must be {words} at every wavelength in 360–830 nm")


def is_texture_object(raw) -> bool:
    """True for a scene file's texture object ({"texture": …} or {"vertex_color": …}) or a TextureInput."""
    return isinstance(raw, TextureInput) or (isinstance(raw, dict) and ("texture" in raw or "vertex_color" in raw))


def _direction(raw, field: str) -> np.ndarray:
    if not isinstance(raw, (list, tuple)) or len(raw) != 3:
        raise SceneError(field, f"must be a list of 3 numbers, got {raw!r}")
    component = Parameter("component", "a vector component")
    v = np.array([component.number(x, f"{field}[{i}]") for i, x in enumerate(raw)])
    norm = np.linalg.norm(v)
    if not norm > 0:
        raise SceneError(field, "must be a non-zero vector")
    return v / norm


class ModelDeclaration:
    """All parameters of one material model, in a stable order (the node's socket order).

    ``name`` is the scene file's material ``type``; ``catalogue`` its name in ``python -m engine
    mueller`` (None: not offered there); ``node`` its Polarising BSDF model enum (None: no node).
    """

    def __init__(self, name: str, title: str, doc: str, parameters, catalogue: str | None = None,
                 node: str | None = None):
        self.name, self.title, self.doc = name, title, doc
        self.parameters = tuple(parameters)
        self.by_name = {p.name: p for p in self.parameters}
        if len(self.by_name) != len(self.parameters):
            raise ValueError(f"{name}: duplicate parameter names")
        self.catalogue, self.node = catalogue, node
        self._build = None
        #: texturable parameters the engine evaluates per surface point today (a model file sets
        #: it after its declaration); a texture on any other parameter is refused with a message
        self.per_point: frozenset[str] = frozenset()

    def __repr__(self):
        return f"ModelDeclaration({self.name!r}, {len(self.parameters)} parameters)"

    def __getitem__(self, name: str) -> Parameter:
        return self.by_name[name]

    def __contains__(self, name: str) -> bool:
        return name in self.by_name

    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def builder(self, function):
        """Decorator: ``function(values, **parts) -> BSDF`` builds the model from :class:`Values`."""
        self._build = function
        return function

    def values(self, data: dict, field: str, text: bool = False, prefix: str = "", label=None,
               base_dir: str | None = None) -> Values:
        return Values(self, data, field, text=text, prefix=prefix, label=label, base_dir=base_dir)

    def build(self, values: Values, **parts):
        """The BSDF (``parts``: assembled materials/coats, e.g. ``coats=…, base=…``)."""
        values.check_meaningful()
        values.check_textures()
        return self._build(values, **parts)


class Values:
    """Validated parameter values of one model read from ``data`` (a scene-file object, flat
    ``NAME=VALUE`` strings where ``text``, or a Blender node's inputs).

    Keys are ``prefix + name``; errors name ``field.<label(name)>`` (``label`` defaults to
    ``prefix + name``; the exporter passes the socket names).
    """

    def __init__(self, model: ModelDeclaration, data: dict, field: str, text: bool = False, prefix: str = "",
                 label=None, base_dir: str | None = None):
        self.model, self.data, self.where, self.text, self.prefix = model, data, field, text, prefix
        self._label = label
        self.base_dir = base_dir    # texture image paths are relative to it (the scene file's folder)

    def field(self, name: str) -> str:
        shown = self._label(name) if self._label is not None else self.prefix + name
        return f"{self.where}.{shown}" if self.where else shown

    def given(self, name: str) -> bool:
        return self.prefix + name in self.data

    def __getitem__(self, name: str):
        return self.get(name)

    def get(self, name: str, default=REQUIRED):
        """The validated value; if not given: ``default`` where passed, else the declared default."""
        p = self.model[name]
        if self.given(name):
            return p.read(self.data[self.prefix + name], self.field(name), self.text, self.base_dir)
        if default is REQUIRED:
            default = p.default
        if default is REQUIRED:
            if p.only_with is not None:
                other, allowed = p.only_with
                raise SceneError(self.field(name), f"is required for {self.prefix}{other} "
                                 f"{' or '.join(map(repr, allowed))} ({p.allowed_text()})")
            raise SceneError(self.field(name), f"is required but missing ({p.allowed_text()})")
        if default is None:
            return None
        return p.read(default, self.field(name))

    def check_textures(self):
        """Refuse textures on parameters the engine does not yet evaluate per point (clear message)."""
        for p in self.model.parameters:
            raw = self.data.get(self.prefix + p.name)
            textures = [i for i, x in enumerate(raw) if is_texture_object(x)] \
                if p.kind == "numbers" and isinstance(raw, (list, tuple)) and p.element.texturable else []
            if textures and p.name not in self.model.per_point:
                raise SceneError(f"{self.field(p.name)}[{textures[0]}]",
                                 "a texture here is not supported by the engine yet; give a constant")
            if p.texturable and self.given(p.name) and is_texture_object(self.data[self.prefix + p.name]) \
                    and p.name not in self.model.per_point:
                supported = ", ".join(sorted(self.model.per_point)) or "none"
                raise SceneError(self.field(p.name), f"a texture on this parameter of {self.model.name!r} is not "
                                                     f"supported by the engine yet (per-point today: {supported}); "
                                                     "give a constant")

    def check_meaningful(self):
        """Reject parameters given where the chosen option ignores them (e.g. m on a smooth coat)."""
        for p in self.model.parameters:
            if p.only_with is not None and self.given(p.name):
                other, allowed = p.only_with
                value = self[other]
                if value not in allowed:
                    raise SceneError(self.field(p.name), f"is only meaningful with {self.prefix}{other} "
                                     f"{' or '.join(map(repr, allowed))}, not {value!r}")


def exterior_n_parameter(**changes) -> Parameter:
    """The index of the incident medium, shared by every interface model."""
    return Parameter("exterior_n", "index of the medium on the side of the normal (incident medium)",
                     lo=0.0, lo_open=True, default=1.0, **changes)


def texture_support_table(models) -> str:
    """A Markdown table of every texturable parameter of ``models`` (declarations, coats included):
    whether the engine evaluates it per surface point today (docs/guide/scene-format.md, "Textures")."""
    rows = ["| model | parameter | kind | per surface point |", "|---|---|---|---|"]

    def walk(decl: ModelDeclaration, title: str):
        for p in decl.parameters:
            if p.kind == "coats" and p.members is not None:
                walk(p.members, f"{title} coat")
            elif p.kind == "numbers" and p.element.texturable:
                state = "yes" if p.name in decl.per_point else "not yet (constant only)"
                rows.append(f"| {title} | `{p.name}` (each) | number | {state} |")
            elif p.texturable:
                state = "yes" if p.name in decl.per_point else "not yet (constant only)"
                kind = "colour/spectrum" if p.kind == "spectrum" else "number"
                rows.append(f"| {title} | `{p.name}` | {kind} | {state} |")
    for decl in models:
        walk(decl, f"`{decl.name}`")
    return "\n".join(rows)
