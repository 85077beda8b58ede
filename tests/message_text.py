"""Comparing the C twins' messages with the Python originals.

The C code (fmu_src/core, fmu_src/native) does not imitate Python's text: it writes numbers with C's %g (exactly:
the first of %.15g .. %.17g that reads back, core/pyfloat.c's exact_number_text) where Python writes repr(x), and a kernel
exception as "Type: text" where Python writes repr(exception), "Type('text')". `canonical` maps a message to what
both must share: the same words, the same numbers (parsed back and compared bit for bit), the same exception types
and texts. An OverflowError's text is CPython's errno and strerror in Python, "(34, 'Numerical result out of
range')", which the C twin does not copy: it says "result out of range"; both become "OverflowError: out of range".
"""
import ast
import math
import re
import struct

# a number as repr or %g write it, not inside a word (a1, fmi2Error and lambda11 stay words)
NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+(?:\.\d*)?(?:[eE][-+]?\d+)?|inf|nan)(?![\w])")
# repr of an exception with one str argument: Type('text') or Type("text")
EXCEPTION_REPR = re.compile(r"\b([A-Z]\w*)\(('(?:[^'\\]|\\.)*'|\"(?:[^\"\\]|\\.)*\")\)")
OVERFLOW = re.compile(r"OverflowError(?:: result out of range|: \(34, 'Numerical result out of range'\)"
                      r"|\(34, 'Numerical result out of range'\))")


def _number(text: str):
    value = float(text)
    return "nan" if math.isnan(value) else struct.pack("<d", value)


def canonical(message: str) -> tuple:
    """The words of a message with every number replaced by its float's bits (module docstring)."""
    message = OVERFLOW.sub("OverflowError: out of range", message)
    while True:  # an exception's repr inside another's text unwraps in a second round
        unwrapped = EXCEPTION_REPR.sub(lambda m: f"{m.group(1)}: {ast.literal_eval(m.group(2))}", message)
        if unwrapped == message:
            break
        message = unwrapped
    parts, end = [], 0
    for match in NUMBER.finditer(message):
        parts += [message[end:match.start()], _number(match.group())]
        end = match.end()
    return tuple(parts + [message[end:]])


def canonical_tree(value):
    """canonical() applied to every str in nested tuples, lists and dicts."""
    if isinstance(value, str):
        return canonical(value)
    if isinstance(value, (tuple, list)):
        return type(value)(canonical_tree(item) for item in value)
    if isinstance(value, dict):
        return {key: canonical_tree(item) for key, item in value.items()}
    return value


class Message(str):
    """A message that equals another str when their canonical forms are equal (for comparing outcomes)."""

    def __eq__(self, other):
        return isinstance(other, str) and canonical(self) == canonical(other)

    def __ne__(self, other):
        return not self == other

    __hash__ = None
