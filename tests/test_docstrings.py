"""Numpy-style docstrings of the public API.

The scanner lists the public callables: the names exported by :mod:`photogeom` and by each
of its sub-packages (``__all__``, or for a module without one its own public names), and
the public methods of the exported classes (with those inherited from private bases such as
``_Polynomial``, which no public name exports). It checks that

* every callable has a docstring;
* a function or method with parameters has a "Parameters" section naming every parameter
  of its signature and none that is not in it (for a class: the parameters of its
  constructor, in a "Parameters" or "Attributes" section of the class or ``__init__``; a
  dataclass extending a dataclass describes only the fields it adds);
* a function or method that returns something has a "Returns" (or "Yields") section.

``ALLOWED`` holds the callables not yet brought to that standard. The list must only
shrink: a name that passes is reported so that it is taken off.
"""

from __future__ import annotations

import ast
import enum
import importlib
import inspect
import re
import textwrap
import types
import typing

PACKAGES = (
    "photogeom",
    "photogeom.adjust",
    "photogeom.bundle",
    "photogeom.calibration",
    "photogeom.camera",
    "photogeom.crs",
    "photogeom.datasets",
    "photogeom.distributed",
    "photogeom.estimation",
    "photogeom.imagecoords",
    "photogeom.io",
    "photogeom.orientation",
    "photogeom.report",
    "photogeom.rotation",
    "photogeom.rpc",
    "photogeom.simulate",
    "photogeom.transforms",
    "photogeom.units",
    # helper modules the docs refer to (docs/cli.md, docs/conventions.md, ...)
    "photogeom.atomicfile",
    "photogeom.io.sources",
    "photogeom.records",
)

_SECTION = re.compile(
    r"^[ \t]*(Parameters|Other Parameters|Returns|Yields|Raises|Warns|Attributes|Notes|"
    r"Examples|See Also|References|Methods)[ \t]*\n[ \t]*-{3,}[ \t]*$",
    re.M,
)


def _sections(doc: str) -> dict[str, str]:
    doc = inspect.cleandoc(doc)
    found = list(_SECTION.finditer(doc))
    out: dict[str, str] = {}
    for i, m in enumerate(found):
        end = found[i + 1].start() if i + 1 < len(found) else len(doc)
        out[m.group(1)] = out.get(m.group(1), "") + doc[m.end() : end]
    return out


def _names_in(block: str) -> set[str]:
    """The entry names of a numpy section: the lines at its smallest indentation."""
    lines = [ln for ln in block.splitlines() if ln.strip()]
    if not lines:
        return set()
    indent = min(len(ln) - len(ln.lstrip()) for ln in lines)
    names: set[str] = set()
    for ln in lines:
        if len(ln) - len(ln.lstrip()) != indent:
            continue
        head = ln.strip().split(" : ")[0].rstrip(":").strip()
        for part in head.split(","):
            names.add(part.strip().lstrip("*"))
    return names


def _params(func) -> list[str]:
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    return [p for p in sig.parameters if p not in ("self", "cls")]


def _returns_value(func) -> bool:
    func = inspect.unwrap(func)
    try:
        hints = typing.get_type_hints(func)
    except Exception:  # unresolvable annotations: fall back to the source
        hints = {}
    ann = getattr(func, "__annotations__", {}).get("return", inspect.Signature.empty)
    if "return" in hints:
        return hints["return"] is not type(None)
    if ann not in (inspect.Signature.empty, None, "None"):
        return True
    if ann in (None, "None"):
        return False
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    except (OSError, TypeError, SyntaxError):
        return False
    top = tree.body[0]
    for node in ast.walk(top):
        if isinstance(node, (ast.Yield, ast.YieldFrom)):
            return True
        if isinstance(node, ast.Return) and node.value is not None:
            # a return inside a nested function does not count
            return True
    return False


def _problems_function(func, *, what: str = "function") -> list[str]:
    doc = inspect.getdoc(func)
    if not doc or not doc.strip():
        return ["no docstring"]
    secs = _sections(doc)
    out = []
    params = _params(func)
    if params:
        if "Parameters" not in secs:
            out.append("no Parameters section")
        else:
            named = _names_in(secs["Parameters"] + secs.get("Other Parameters", ""))
            missing = [p for p in params if p not in named]
            extra = sorted(named - set(params))
            if missing:
                out.append(f"parameters not described: {missing}")
            if extra:
                out.append(f"described but not in the signature: {extra}")
    if what != "class" and _returns_value(func) and not ({"Returns", "Yields"} & set(secs)):
        out.append("no Returns section")
    return out


def _problems_class(cls) -> list[str]:
    doc = cls.__doc__
    if not doc or not doc.strip():
        return ["no docstring"]
    if issubclass(cls, (BaseException, enum.Enum)):
        return []
    init = cls.__dict__.get("__init__")
    params = _params(cls) if init is not None or "__dataclass_fields__" in vars(cls) else []
    if "__dataclass_fields__" in vars(cls) and any(
        hasattr(b, "__dataclass_fields__") for b in cls.__bases__
    ):
        # a dataclass extending a dataclass: the inherited fields are the base's to describe
        own = vars(cls).get("__annotations__", {})
        params = [p for p in params if p in own]
    if not params:
        return []
    secs = _sections(doc)
    init_doc = inspect.getdoc(init) if init is not None and init.__doc__ else ""
    init_secs = _sections(init_doc) if init_doc else {}
    blocks = [s.get(k, "") for s in (secs, init_secs) for k in ("Parameters", "Attributes")]
    if not any(blocks):
        return ["no Parameters or Attributes section for the constructor"]
    named = set().union(*(_names_in(b) for b in blocks if b))
    missing = [p for p in params if p not in named and not p.startswith("_")]
    return [f"constructor parameters not described: {missing}"] if missing else []


def _exported(pkg: str) -> list[tuple[str, object]]:
    mod = importlib.import_module(pkg)
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [
            n
            for n, v in vars(mod).items()
            if not n.startswith("_") and getattr(v, "__module__", None) == pkg
        ]
    out = []
    for n in names:
        if n.startswith("_"):
            continue
        v = getattr(mod, n)
        if isinstance(v, types.ModuleType):
            continue
        if inspect.isclass(v) or inspect.isfunction(v) or inspect.isbuiltin(v):
            out.append((n, v))
    return out


def public_callables() -> dict[str, object]:
    """``{qualified name: object}`` of every public callable the scanner checks."""
    found: dict[str, object] = {}
    for pkg in PACKAGES:
        for name, obj in _exported(pkg):
            key = f"{pkg}.{name}"
            if any(obj is v for v in found.values()):
                continue  # re-exported: checked once, under its first name
            found[key] = obj
            if inspect.isclass(obj) and not issubclass(obj, (BaseException, enum.Enum)):
                # its own methods, and those it inherits from private photogeom bases (which
                # no public name exports)
                owners = [obj] + [
                    b
                    for b in obj.__mro__[1:]
                    if b.__name__.startswith("_") and b.__module__.startswith("photogeom")
                ]
                for owner in owners:
                    for mname, member in vars(owner).items():
                        if mname.startswith("_") or f"{key}.{mname}" in found:
                            continue
                        if any(mname in vars(c) for c in obj.__mro__[: obj.__mro__.index(owner)]):
                            continue  # overridden by a class before the owner
                        if isinstance(member, (staticmethod, classmethod)):
                            member = member.__func__
                        if inspect.isfunction(member) and not any(
                            member is v for v in found.values()
                        ):
                            found[f"{key}.{mname}"] = member
    return found


def problems(obj) -> list[str]:
    if inspect.isclass(obj):
        return _problems_class(obj)
    return _problems_function(obj)


# Callables not yet documented to the standard (empty since the bundle, adjust and relative
# orientation docstrings were completed since). The list must only shrink.
ALLOWED: frozenset[str] = frozenset()


def _scan() -> dict[str, list[str]]:
    return {k: p for k, obj in public_callables().items() if (p := problems(obj))}


def test_scanner_finds_the_public_api():
    found = public_callables()
    assert "photogeom.space_resection" in found
    assert "photogeom.Similarity3D.apply" in found
    assert len(found) > 300


def test_scanner_detects_missing_sections():
    def bare(a, b=1):
        """Does something with a and b."""
        return a + b

    def wrong(a):
        """Do it.

        Parameters
        ----------
        a : float
            A, in m.
        c : int
            Not a parameter.

        Returns
        -------
        float
            The result, m.
        """
        return a

    def good(a, *, b=2):
        """Do it.

        Parameters
        ----------
        a, b : float
            Values, m.

        Returns
        -------
        float
            Sum, m.
        """
        return a + b

    assert problems(bare) == ["no Parameters section", "no Returns section"]
    assert problems(wrong) == ["described but not in the signature: ['c']"]
    assert problems(good) == []


def test_public_api_docstrings_are_numpy_style():
    bad = _scan()
    new = {k: v for k, v in bad.items() if k not in ALLOWED}
    assert not new, "public callables without numpy-style docstrings:\n" + "\n".join(
        f"  {k}: {'; '.join(v)}" for k, v in sorted(new.items())
    )


def test_allow_list_only_shrinks():
    bad = _scan()
    found = public_callables()
    stale = sorted(k for k in ALLOWED if k not in bad or k not in found)
    assert not stale, "documented now (or gone): take off ALLOWED:\n" + "\n".join(stale)


if __name__ == "__main__":  # pragma: no cover - prints the current list
    for key, probs in sorted(_scan().items()):
        print(f"{key}\t{'; '.join(probs)}")
