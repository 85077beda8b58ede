"""ctypes layouts of the compiled core's structures, generated from its C headers (fmu_src/core/*.h).

vibromodel's ctypes front ends (compiled.py, compiled_open_loop.py, compiled_loop.py) read and write the core's
structures field by field. Their layouts are not typed by hand: `layouts_module()` reads the `typedef struct`
declarations, the integer and float `#define`s and the `enum` constants of the headers and writes them as the
Python module fmu_src/vibromodel/core_layouts.py, which is committed (the FMUs carry it with vibromodel, so they
need neither this generator nor any C parser at run time, and a checkout works without a build step).
tests/core/test_core_layouts.py fails when the committed module is not what the headers give, and checks every size
and offset against the C compiler's own sizeof/offsetof. Regenerate with `python3 -m vibrofmu.fmus.layouts`.

Why a small parser of our own and not pycparser or cffi: the headers include <stdint.h> and <stddef.h>, which
pycparser cannot read without a preprocessor and fake libc headers, and cffi would be a run-time dependency of
the FMU if it built the layouts there. The structures are simple (scalars, fixed arrays, pointers, nested
typedef'd structures), so a parser of that subset is short, and anything outside it is refused by name.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from vibrofmu import paths

CORE = paths.FMU_SRC / "core"
MODULE = paths.vibromodel_dir() / "core_layouts.py"  # the vibromodel the FMUs carry
# The headers with structures or constants the front ends use (the others hold functions only).
HEADERS = ("dop853.h", "rk4.h", "model.h", "plant.h", "slowflow_eval.h", "oafm_eval.h", "openloop_plant.h",
           "controller.h", "closedloop.h")
SCALARS = {"double": "ctypes.c_double", "int64_t": "ctypes.c_int64", "char": "ctypes.c_char",
           "size_t": "ctypes.c_size_t", "int": "ctypes.c_int"}


class LayoutError(ValueError):
    """A header declaration outside the subset this generator reads (names the header and the text)."""


@dataclass(frozen=True)
class Field:
    name: str
    type: str              # a SCALARS key or a structure's name
    pointer: bool
    dims: tuple[str, ...]  # array dimensions, outermost first (numbers or constant names)


@dataclass(frozen=True)
class Struct:
    name: str
    header: str
    fields: tuple[Field, ...]


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    return re.sub(r"//[^\n]*", " ", text)


_NAME = r"[A-Za-z_]\w*"
_DECLARATOR = re.compile(rf"^(\*?)\s*({_NAME})\s*((?:\[\s*\w+\s*\]\s*)*)$")


def _fields(header: str, body: str) -> tuple[Field, ...]:
    fields = []
    for declaration in filter(None, (part.strip() for part in body.split(";"))):
        match = re.match(rf"^(?:const\s+)?({_NAME})\s+(.*)$", declaration, flags=re.S)
        if not match:
            raise LayoutError(f"{header}: cannot read the field declaration {declaration!r}")
        kind, rest = match.groups()
        for declarator in rest.split(","):
            parts = _DECLARATOR.match(" ".join(declarator.split()))
            if not parts:
                raise LayoutError(f"{header}: cannot read the declarator {declarator.strip()!r} of {declaration!r}")
            star, name, dims = parts.groups()
            fields.append(Field(name, kind, bool(star), tuple(re.findall(r"\[\s*(\w+)\s*\]", dims))))
    return tuple(fields)


def read_headers(directory: Path = CORE, headers=HEADERS) -> tuple[list[tuple[str, str, str]], list[Struct]]:
    """(constants, structures) of the headers, in header order then declaration order. A constant is
    (header, name, Python value text): `#define NAME number-or-name` and enum members (implicit values count on)."""
    constants, structs = [], []
    for header in headers:
        text = _strip_comments((Path(directory) / header).read_text())
        for name, value in re.findall(rf"^\s*#define\s+({_NAME})[ \t]+([^\n]+?)\s*$", text, flags=re.M):
            if re.fullmatch(r"-?\d+(\.\d*)?([eE][-+]?\d+)?|" + _NAME, value):
                constants.append((header, name, value))
        for body in re.findall(r"\benum\s*\{(.*?)\}", text, flags=re.S):
            following = None
            for member in filter(None, (part.strip() for part in body.split(","))):
                match = re.fullmatch(rf"({_NAME})\s*(?:=\s*(-?\d+|{_NAME}))?", member)
                if not match:
                    raise LayoutError(f"{header}: cannot read the enum member {member!r}")
                name, value = match.groups()
                value = value if value is not None else (following if following is not None else "0")
                constants.append((header, name, value))
                following = f"{name} + 1"
        for body, name in re.findall(rf"\btypedef\s+struct\s*(?:{_NAME}\s*)?\{{(.*?)\}}\s*({_NAME})\s*;", text,
                                     flags=re.S):
            if "{" in body:
                raise LayoutError(f"{header}: {name} has a nested anonymous structure or union")
            structs.append(Struct(name, header, _fields(header, body)))
    return constants, structs


def _ctype(field: Field, known: set[str]) -> str:
    if field.type in SCALARS:
        base = SCALARS[field.type]
    elif field.type in known:
        base = field.type
    else:
        raise LayoutError(f"field {field.name}: type {field.type} is neither a scalar nor a structure declared before")
    if field.pointer:
        base = f"ctypes.POINTER({base})"
    for dim in reversed(field.dims):  # double k[A][B] is (c_double * B) * A
        base = f"({base}) * {dim}" if " * " in base else f"{base} * {dim}"
    return base


def layouts_module(directory: Path = CORE, headers=HEADERS) -> str:
    """The text of vibromodel/core_layouts.py."""
    constants, structs = read_headers(directory, headers)
    lines = [
        '"""The compiled core\'s constants and structures as ctypes: GENERATED from fmu_src/core/*.h by',
        "harness/vibrofmu/fmus/layouts.py (python3 -m vibrofmu.fmus.layouts); do not edit. tests/core/test_core_layouts.py",
        'checks that this module is current and that every size and offset is the C compiler\'s."""',
        "import ctypes",
        "",
    ]
    header = None
    for where, name, value in constants:
        if where != header:
            lines += ["", f"# {where}"]
            header = where
        lines.append(f"{name} = {value}")
    known: set[str] = set()
    for struct in structs:
        rows = _rows([(field.name, _ctype(field, known)) for field in struct.fields])
        lines += ["", "", f"class {struct.name}(ctypes.Structure):", f'    """{struct.header}\'s {struct.name}."""',
                  "    _fields_ = [", *rows, "    ]"]
        known.add(struct.name)
    lines += ["", "", "STRUCTURES = (" + ", ".join(struct.name for struct in structs) + ",)"]
    return _wrap("\n".join(lines) + "\n")


def _rows(fields: list[tuple[str, str]]) -> list[str]:
    """The lines of a _fields_ list: a run of consecutive fields of one ctypes type is one line
    `*[(name, type) for name in (...)]` (the same fields in the same order), any other field a tuple of its own."""
    rows, i = [], 0
    while i < len(fields):
        j = i
        while j < len(fields) and fields[j][1] == fields[i][1]:
            j += 1
        if j - i >= 3:
            names = ", ".join(f'"{name}"' for name, _ in fields[i:j])
            rows.append(f"        *[(name, {fields[i][1]}) for name in ({names})],")
        else:
            rows += [f'        ("{name}", {ctype}),' for name, ctype in fields[i:j]]
        i = j
    return rows


def _wrap(text: str, width: int = 120) -> str:
    """Break a long line (STRUCTURES) at commas so that the module stays within the project's line width."""
    out = []
    for line in text.splitlines():
        while len(line) > width and ", " in line[:width]:
            cut = line[:width].rindex(", ") + 1
            out.append(line[:cut])
            line = "    " + line[cut:].lstrip()
        out.append(line)
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    MODULE.write_text(layouts_module())
    print(f"wrote {MODULE}")
