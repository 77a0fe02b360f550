"""IO description files of FinEmbP nodes (docs/finemb.md): a small TOML file naming the
application and its ports, read into a :class:`hdl.finemb.IoDescriptor`.

```toml
name = "pid"
[[port]]
name = "set_point"
direction = "out"        # master -> node (output page); "in": node -> master
type = "i16"             # bool, u8, i8, u16, i16, u32, i32, f32, f64, or blob with a size
```
"""

import tomllib
from pathlib import Path

from hdl.finemb import IoDescriptor
from hdl.params import ParameterError

__all__ = ["IoDescriptionError", "load_io_description", "parse_io_description"]


class IoDescriptionError(ValueError):
    """An IO description file is not valid; the message names the file, the line and what is
    wrong."""


def _lines(text):
    """Where each ``[[port]]`` table starts, and the line of each key in it:
    ``[(header line, {key: line})]``, and the top-level keys' lines."""
    top, tables = {}, []
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.split("#", 1)[0].strip()
        if stripped.startswith("[[") and stripped.rstrip().endswith("]]"):
            tables.append((number, {}))
        elif "=" in stripped:
            key = stripped.split("=", 1)[0].strip().strip('"')
            (tables[-1][1] if tables else top).setdefault(key, number)
    return top, tables


def parse_io_description(text, path="io.toml"):
    """The :class:`IoDescriptor` of description ``text`` (named ``path`` in errors)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise IoDescriptionError(f"{path}: {exc}") from None
    top, tables = _lines(text)

    def where(k=None, key=None):
        if k is None:
            return f"{path}:{top.get(key, 1)}"
        header, keys = tables[k] if k < len(tables) else (1, {})
        return f"{path}:{keys.get(key, header)}: port {k + 1}"

    unknown = set(doc) - {"name", "port"}
    if unknown:
        key = sorted(unknown)[0]
        raise IoDescriptionError(f"{where(key=key)}: unknown key {key!r}; expected name and "
                                 f"[[port]] tables")
    if "name" not in doc:
        raise IoDescriptionError(f"{path}:1: missing 'name' (the application's name)")
    ports = doc.get("port", [])
    if not isinstance(ports, list):
        raise IoDescriptionError(f"{where(key='port')}: 'port' must be [[port]] tables")
    specs = []
    for k, port in enumerate(ports):
        if not isinstance(port, dict):
            raise IoDescriptionError(f"{where(k)}: expected a [[port]] table")
        extra = set(port) - {"name", "direction", "type", "size"}
        if extra:
            key = sorted(extra)[0]
            raise IoDescriptionError(f"{where(k, key)}: unknown key {key!r}; expected name, "
                                     f"direction, type and (blobs) size")
        for key in ("name", "direction", "type"):
            if key not in port:
                raise IoDescriptionError(f"{where(k)}: missing {key!r}")
        spec = (port["name"], port["direction"], port["type"])
        if "size" in port:
            spec += (port["size"],)
        specs.append(spec)
    try:
        return IoDescriptor(doc["name"], specs)
    except ParameterError as exc:
        # IoDescriptor names the port as "ports[k] (name) field": point at that line
        k = key = None
        if exc.name.startswith("ports["):
            k = int(exc.name[6:exc.name.index("]")])
            words = exc.name.split()
            key = words[-1] if len(words) > 1 and words[-1] in ("direction", "type", "size",
                                                                  "name") else None
        elif exc.name == "name":
            key = "name"
        raise IoDescriptionError(f"{where(k, key)}: {exc}") from None


def load_io_description(path):
    """Read the IO description file ``path``."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise IoDescriptionError(f"{path}: cannot read it: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        line = path.read_bytes()[:exc.start].count(b"\n") + 1
        raise IoDescriptionError(f"{path}:{line}: not a text file (byte {exc.start} is not "
                                 f"UTF-8); an IO description is TOML text") from None
    return parse_io_description(text, path)
