"""MJCF as an element tree with line numbers, ``<include>`` expanded and ``<default>``
classes resolved.

* :func:`read_document` parses a file (or MJCF text) with the standard library's expat
  parser, recording every element's file and line (``element.where``, e.g.
  ``"hopper.xml:42"``), and replaces each ``<include file=...>`` by the children of the
  included file's ``<mujoco>`` (paths relative to the including file).
* :class:`Defaults` holds the ``<default>`` classes: a class's attributes for a tag are its
  parent class's, updated by its own; ``main`` is the top-level class.
  :meth:`Defaults.attributes` gives an element's attributes with its class's defaults under
  them (the element's ``class``, else the nearest ``childclass`` of its enclosing bodies).
* Every tag must be one MJCF defines (:data:`KNOWN_TAGS`); an unknown tag is an error naming
  it and its line.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path
from xml.parsers import expat

import numpy as np

from ncgen.errors import ModelError

#: Every element MJCF defines (MuJoCo 3.x/4.x schema, all sections).
KNOWN_TAGS = frozenset("""
mujoco compiler lengthrange option flag size visual global quality headlight map scale rgba statistic
default asset mesh hfield skin texture material model layer bone vertex texcoord face worldbody body frame
inertial joint freejoint geom site camera light attach composite flexcomp replicate plugin instance config pin
contact pair exclude deformable flex edge elasticity equality connect weld tendon distance spatial fixed pulley
actuator general motor position velocity intvelocity damper cylinder muscle adhesion dcmotor sensor touch
accelerometer velocimeter gyro force torque magnetometer rangefinder camprojection jointpos jointvel tendonpos
tendonvel actuatorpos actuatorvel actuatorfrc jointactuatorfrc tendonactuatorfrc ballquat ballangvel
jointlimitpos jointlimitvel jointlimitfrc tendonlimitpos tendonlimitvel tendonlimitfrc framepos framequat
framexaxis frameyaxis framezaxis framelinvel frameangvel framelinacc frameangacc subtreecom subtreelinvel
subtreeangmom insidesite normal fromto e_potential e_kinetic clock user tactile keyframe key custom numeric
text tuple element extension include
""".split())

#: Actuator tags; their defaults are the class's ``general`` attributes under the tag's own.
ACTUATOR_TAGS = ("general", "motor", "position", "velocity", "intvelocity", "damper", "cylinder", "muscle",
                 "adhesion", "dcmotor")


class Element(ET.Element):
    """An element that knows its ``file:line`` (``where``)."""

    where = "?"


def where(el) -> str:
    """``file:line`` of an element."""
    return getattr(el, "where", "?")


def _parse(text: str, name: str):
    """The root element of MJCF ``text``; every element carries ``where``."""
    stack: list = []
    root = []
    parser = expat.ParserCreate()

    def start(tag, attrs):
        el = Element(tag, attrs)
        el.where = f"{name}:{parser.CurrentLineNumber}"
        if stack:
            stack[-1].append(el)
        else:
            root.append(el)
        stack.append(el)

    def end(tag):
        stack.pop()

    parser.StartElementHandler, parser.EndElementHandler = start, end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as e:
        raise ModelError(f"MJCF {name}:{e.lineno}: not well-formed XML ({expat.errors.messages[e.code]})") from None
    return root[0]


def read_document(source):
    """``(root, directory, name)``: the ``<mujoco>`` element of a path or of MJCF text, with
    includes expanded and tags checked (module docstring)."""
    text = str(source)
    if "<" in text:
        directory, name = Path.cwd(), "text"
    else:
        path = Path(source)
        if not path.is_file():
            raise ModelError(f"MJCF: no file {str(path)!r} (expected a path to an MJCF .xml file or MJCF text)")
        directory, name = path.parent, path.name
        text = _read(path, name)
    root = _parse(text, name)
    if root.tag != "mujoco":
        raise ModelError(f"MJCF {where(root)}: expected a <mujoco> root element, found <{root.tag}>")
    _expand_includes(root, directory, [name])
    for el in root.iter():
        if el.tag not in KNOWN_TAGS:
            raise ModelError(f"MJCF {where(el)}: unknown element <{el.tag}> (not an MJCF element)")
    return root, directory, name


def included_files(path) -> list[str]:
    """The files that ``<include file=...>`` elements of the MJCF file ``path`` name, and
    theirs, resolved (found by their text, without parsing: what a store keyed by the
    file's contents must key too); a file that cannot be read is left to the reader."""
    out, todo = [], [Path(path)]
    while todo:
        current = todo.pop()
        try:
            text = current.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            continue
        for file in INCLUDE.findall(text):
            found = str((current.parent / file).resolve())
            if found not in out:
                out.append(found)
                todo.append(Path(found))
    return out


#: An ``<include file="...">`` element's file, in the text.
INCLUDE = re.compile(r"<include\s[^>]*?file\s*=\s*[\"']([^\"']+)[\"']")


def _read(path: Path, name: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ModelError(f"MJCF {name}: cannot read it: {e}") from None


def _expand_includes(parent, directory: Path, chain: list[str]) -> None:
    for k, el in enumerate(list(parent)):
        if el.tag != "include":
            _expand_includes(el, directory, chain)
            continue
        file = el.get("file")
        if not file:
            raise ModelError(f"MJCF {where(el)}: <include> has no file attribute")
        path = directory / file
        if not path.is_file():
            raise ModelError(f"MJCF {where(el)}: <include file={file!r}>: no file {str(path)!r}")
        if path.name in chain:
            raise ModelError(f"MJCF {where(el)}: <include file={file!r}> includes itself (through {' → '.join(chain)})")
        sub = _parse(_read(path, path.name), path.name)
        if sub.tag != "mujoco":
            raise ModelError(f"MJCF {where(sub)}: an included file must have a <mujoco> root, found <{sub.tag}>")
        _expand_includes(sub, path.parent, chain + [path.name])
        index = list(parent).index(el)
        parent.remove(el)
        for i, child in enumerate(list(sub)):
            parent.insert(index + i, child)


class Defaults:
    """The ``<default>`` classes of a document (module docstring)."""

    def __init__(self, root):
        self.classes: dict[str, dict[str, dict]] = {}
        self.where: dict[str, str] = {}
        for top in root.findall("default"):
            self._read(top, "main", {})

    def _read(self, el, name: str, inherited: dict) -> None:
        if name in self.classes and name != "main":
            raise ModelError(f"MJCF {where(el)}: <default class={name!r}> is defined twice "
                             f"(first at {self.where[name]})")
        own = {tag: dict(attrs) for tag, attrs in {**inherited, **self.classes.get(name, {})}.items()}
        for child in el:
            if child.tag != "default":
                own.setdefault(child.tag, {}).update(child.attrib)
        self.classes[name] = own
        self.where.setdefault(name, where(el))
        for child in el:
            if child.tag == "default":
                cls = child.get("class")
                if not cls:
                    raise ModelError(f"MJCF {where(child)}: a nested <default> has no class attribute")
                self._read(child, cls, own)

    def attributes(self, el, childclass: str | None = None) -> dict:
        """``el``'s attributes over its class's defaults (module docstring)."""
        cls = el.get("class") or childclass or "main"
        if cls not in self.classes:
            if cls == "main":
                return dict(el.attrib)
            raise ModelError(f"MJCF {where(el)}: <{el.tag}> uses class {cls!r}, which no <default> defines")
        table = self.classes[cls]
        out = {}
        if el.tag in ACTUATOR_TAGS:
            out.update(table.get("general", {}))
        if el.tag != "freejoint":          # a freejoint takes no defaults
            out.update(table.get(el.tag, {}))
        out.update(el.attrib)
        out.pop("class", None)
        return out


def numbers(el, attrs: dict, key: str, n: int | tuple | None = None, default=None) -> np.ndarray | None:
    """The finite numbers of attribute ``key`` (``n``: the count, or the allowed counts;
    None: any); ``default`` when absent.  Errors name the element, its line and the text."""
    text = attrs.get(key)
    if text is None:
        return None if default is None else np.asarray(default, float)
    try:
        vals = [float(s) for s in text.split()]
    except ValueError:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {key}={text!r}>: expected numbers") from None
    allowed = (n,) if isinstance(n, int) else n
    if allowed is not None and len(vals) not in allowed:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {key}={text!r}>: expected "
                         f"{' or '.join(map(str, allowed))} number(s), found {len(vals)}")
    if not all(math.isfinite(x) for x in vals):
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {key}={text!r}>: expected finite numbers")
    return np.array(vals)


def number(el, attrs: dict, key: str, default: float) -> float:
    """One finite number (attribute ``key``), ``default`` when absent."""
    v = numbers(el, attrs, key, 1)
    return float(default) if v is None else float(v[0])


def choice(el, attrs: dict, key: str, allowed: tuple, default: str) -> str:
    """Attribute ``key``, one of ``allowed``."""
    v = attrs.get(key, default)
    if v not in allowed:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {key}={v!r}>: expected one of {', '.join(allowed)}")
    return v
