"""Read a configuration file (JSON or YAML) into plain dicts, strictly.

Stricter than ``yaml.safe_load`` in three ways, each a silent misreading otherwise: a key given
twice is refused (YAML and ``json`` keep the last one); ``1e-3`` is a float (YAML 1.1 wants a dot
and a signed exponent, so it read ``1e-3`` as a string and refused JSON's exponents); and a file
that is not UTF-8 text is refused by name. ``.json`` files are parsed by ``json`` (which also
allows the tabs that YAML does not), everything else as YAML.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import yaml

from generator.errors import ConfigError


class _Pairs(list):
    """A mapping as parsed, before duplicate keys are checked: a list of ``(key, value)``."""


class _Loader(yaml.SafeLoader):
    """Safe YAML with YAML 1.2 exponent floats, mappings kept as ``_Pairs``."""


#: A number in exponent notation (``3e-4``, ``1.5E+3``): a float in YAML 1.2 and JSON, a string in
#: the YAML 1.1 that PyYAML reads; add it to a loader with :func:`read_exponent_floats`.
EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")


def read_exponent_floats(loader: type[yaml.SafeLoader]) -> None:
    """Make ``loader`` (a ``SafeLoader`` subclass) read :data:`EXPONENT_FLOAT` numbers as floats."""
    loader.add_implicit_resolver("tag:yaml.org,2002:float", EXPONENT_FLOAT, list("-+0123456789."))


read_exponent_floats(_Loader)
_Loader.add_constructor("tag:yaml.org,2002:map", lambda loader, node: _Pairs(loader.construct_pairs(node, deep=True)))


def _unique(value: Any, source: str, prefix: str = "") -> Any:
    """``value`` with every ``_Pairs`` turned into a dict; a repeated key raises, named in full."""
    if isinstance(value, _Pairs):
        out: dict[str, Any] = {}
        for key, item in value:
            name = f"{prefix}{key}"
            if not isinstance(key, str):
                raise ConfigError(name, f"keys must be strings in {source}, got {type(key).__name__}")
            if key in out:
                raise ConfigError(name, f"duplicate key in {source}")
            out[key] = _unique(item, source, name + ".")
        return out
    if isinstance(value, list):
        return [_unique(v, source, prefix) for v in value]
    return value


def read_config_file(path: str | Path) -> Any:
    """The parsed contents of ``path`` (``{}`` for an empty YAML file); ``ConfigError`` naming
    the file if it cannot be read or parsed, or naming the key that appears twice."""
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except OSError as exc:
        raise ConfigError(str(path), f"cannot read configuration: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(str(path), f"not a UTF-8 text file (byte {exc.object[exc.start]:#04x} at offset "
                                     f"{exc.start})") from exc
    try:
        if str(path).lower().endswith(".json"):
            data = json.loads(text, object_pairs_hook=_Pairs)
        else:
            data = yaml.load(text, Loader=_Loader)
    except (ValueError, yaml.YAMLError) as exc:
        raise ConfigError(str(path), f"cannot parse configuration: {exc}") from exc
    return {} if data is None else _unique(data, str(path))


def parse_config_value(text: str, source: str) -> Any:
    """One value written as a configuration file would hold it (``1e-4`` a number, ``[0, 1]`` a
    list, ``true`` a boolean, other words strings), e.g. from a ``--set KEY=VALUE`` flag;
    ``ConfigError`` naming ``source`` when it does not parse."""
    try:
        return _unique(yaml.load(text, Loader=_Loader), source)
    except yaml.YAMLError as exc:
        raise ConfigError(source, f"cannot parse {text!r}: {exc}") from exc


def shipped_or_file(name_or_path: str | Path, folder: Path) -> Path:
    """A shipped file by name (``folder/<name>.yml``) or a file's path; ``FileNotFoundError``
    naming it, and the shipped names, when there is neither."""
    shipped = folder / f"{name_or_path}.yml"
    path = shipped if shipped.is_file() else Path(name_or_path)
    if not path.is_file():
        names = sorted(p.stem for p in folder.glob("*.yml"))
        raise FileNotFoundError(f"no recipe file {name_or_path} (shipped recipes: {', '.join(names)})")
    return path
