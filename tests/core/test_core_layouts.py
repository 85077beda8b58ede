"""vibromodel/core_layouts.py, the ctypes structures and constants generated from fmu_src/core/*.h
(harness/vibrofmu/fmus/layouts.py): current with the headers, and every size, offset and constant equal to what
the C compiler makes of the headers themselves (an independent check of the generator)."""
import ctypes
import subprocess

import pytest

from vibrofmu.fmus import toolchain
from vibrofmu.fmus import layouts
from vibromodel import compiled_loop, control, core_layouts


def test_the_committed_module_is_generated_from_the_headers():
    """Fails when a header changed and the module was not regenerated (python3 -m vibrofmu.fmus.layouts)."""
    assert layouts.MODULE.read_text() == layouts.layouts_module()


def _paths(structure, prefix=""):
    """(C member designator, ctypes offset, ctypes size) of every field of a structure, nested structures
    included (arrays of structures through their element 1, so that the stride is checked too)."""
    for name, kind in structure._fields_:
        field = getattr(structure, name)
        path = prefix + name
        yield path, field.offset, field.size
        element = kind
        if issubclass(kind, ctypes.Array) and issubclass(kind._type_, ctypes.Structure):
            element, path = kind._type_, path + "[1]"
            yield path, field.offset + ctypes.sizeof(element), ctypes.sizeof(element)
        if issubclass(element, ctypes.Structure):
            base = field.offset if element is kind else field.offset + ctypes.sizeof(element)
            for sub, offset, size in _paths(element, path + "."):
                yield sub, base + offset, size


def test_sizes_offsets_and_constants_are_the_compilers(tmp_path):
    """A C program over the same headers prints sizeof and offsetof of every field the module declares, and the
    value of every constant; all must equal the module's."""
    constants, _ = layouts.read_headers()
    expected, lines = [], []
    for structure in core_layouts.STRUCTURES:
        name = structure.__name__
        expected.append(f"{name} {ctypes.sizeof(structure)}")
        lines.append(f'    printf("{name} %zu\\n", sizeof({name}));')
        for path, offset, size in _paths(structure):
            expected.append(f"{name}.{path} {offset} {size}")
            lines.append(f'    printf("{name}.{path} %zu %zu\\n", offsetof({name}, {path}), '
                         f"sizeof((({name} *)0)->{path}));")
    for _, name, _ in constants:
        value = getattr(core_layouts, name)
        expected.append(f"{name} {value!r}")
        form = '"%.1f"' if isinstance(value, float) else '"%lld"'
        cast = "(double)" if isinstance(value, float) else "(long long)"
        lines.append(f'    printf("{name} " {form} "\\n", {cast}({name}));')
    includes = "".join(f'#include "{header}"\n' for header in layouts.HEADERS)
    source = tmp_path / "layouts.c"
    source.write_text("#include <stddef.h>\n#include <stdio.h>\n" + includes + "int main(void)\n{\n"
                      + "\n".join(lines) + "\n    return 0;\n}\n")
    program = tmp_path / "layouts"
    subprocess.run([*toolchain.c_compiler(), "-std=c11", "-I", str(layouts.CORE), "-o", str(program), str(source)],
                   check=True, capture_output=True, text=True)
    printed = subprocess.run([str(program)], check=True, capture_output=True, text=True).stdout.splitlines()
    assert printed == expected
    assert len(printed) > 300  # every structure's fields were compared (not an empty list against an empty one)


def test_the_front_ends_names_fit_the_headers_arrays():
    """The names the front ends give the arrays' entries are as many as the headers' arrays hold."""
    assert len(control.ESTIMATE_NAMES) == core_layouts.VC_N
    assert len(compiled_loop.CONTROLLER_INPUTS) == core_layouts.VC_INPUTS
    assert len(compiled_loop.CONTROLLER_OUTPUTS) == core_layouts.VC_OUTPUTS
    assert len(compiled_loop.LOOP_OUTPUTS) == core_layouts.VL_OUTPUTS


@pytest.mark.parametrize("declaration, complaint", [
    ("typedef struct { float x; } Bad;", "type float"),
    ("typedef struct { union { double a; int64_t b; } u; } Bad;", "nested anonymous"),
    ("typedef struct { double (*f)(double); } Bad;", "cannot read the declarator"),
])
def test_the_generator_refuses_what_it_cannot_read(tmp_path, declaration, complaint):
    (tmp_path / "bad.h").write_text(f"#include <stdint.h>\n{declaration}\n")
    with pytest.raises(layouts.LayoutError, match=complaint):
        layouts.layouts_module(tmp_path, ("bad.h",))
