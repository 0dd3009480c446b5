"""Every public name has a numpydoc docstring that documents its parameters and returns."""

from __future__ import annotations

import dataclasses
import enum
import importlib
import inspect
import pkgutil

import pytest
from numpydoc.docscrape import ClassDoc
from numpydoc.validate import validate

import backlashkit

#: numpydoc checks enforced: a docstring exists, has a summary, documents exactly the
#: parameters of the signature, and documents what functions return.
ENFORCED = {"GL08", "SS01", "PR01", "PR02", "PR03", "RT01", "RT03"}


def _public_modules() -> tuple[str, ...]:
    """Every public module of the package (no ``_`` part; the CLI only words results)."""
    names = []
    for info in pkgutil.walk_packages(backlashkit.__path__, "backlashkit."):
        parts = info.name.split(".")[1:]
        if any(p.startswith("_") for p in parts) or parts[0] == "cli":
            continue
        names.append(".".join(parts))
    return tuple(names)


#: Public modules whose ``__all__`` is documented API besides the package's own.
SUBMODULES = _public_modules()


def _exported():
    for name in backlashkit.__all__:
        if not name.startswith("__"):
            yield name, getattr(backlashkit, name)
    for mod in SUBMODULES:
        module = importlib.import_module(f"backlashkit.{mod}")
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name)
            if callable(obj) and getattr(obj, "__module__", "") == module.__name__:
                yield f"{mod}.{name}", obj


def public_objects():
    for name, obj in _exported():
        yield f"backlashkit.{name}", obj
        if inspect.isclass(obj) and not issubclass(obj, enum.Enum):
            # own methods and those inherited from backlashkit's own base classes
            seen: set[str] = set()
            for klass in obj.__mro__:
                if not klass.__module__.startswith("backlashkit"):
                    continue
                for attr, member in vars(klass).items():
                    if attr.startswith("_") or attr in seen:
                        continue
                    seen.add(attr)
                    if inspect.isfunction(member) or isinstance(
                        member, (classmethod, staticmethod)
                    ):
                        yield f"backlashkit.{name}.{attr}", member


@pytest.mark.parametrize("qualname", [q for q, _ in public_objects()])
def test_public_docstring(qualname):
    for mod in SUBMODULES:
        importlib.import_module(f"backlashkit.{mod}")
    obj = eval(qualname, {"backlashkit": backlashkit})  # noqa: S307 - our own names
    errors = [(code, msg) for code, msg in validate(qualname)["errors"] if code in ENFORCED]
    if inspect.isclass(obj) and issubclass(obj, enum.Enum):
        # an Enum's signature is the functional API (names, module, ...): not its docs
        errors = [e for e in errors if e[0] not in {"PR01", "PR02"}]
    if dataclasses.is_dataclass(obj) and inspect.isclass(obj):
        # a result object documents its fields as Attributes (python-control's style)
        documented = {n.strip() for item in ClassDoc(obj)["Attributes"]
                      for n in item.name.split(",")}
        fields = {f.name for f in dataclasses.fields(obj) if f.init}
        if fields <= documented:
            errors = [e for e in errors if e[0] not in {"PR01", "PR02"}]
    assert not errors, errors


def test_every_public_name_is_exported_and_typed():
    assert len(set(backlashkit.__all__)) == len(backlashkit.__all__)
    for name in backlashkit.__all__:
        assert hasattr(backlashkit, name), name
    from importlib.resources import files

    assert files("backlashkit").joinpath("py.typed").is_file()
