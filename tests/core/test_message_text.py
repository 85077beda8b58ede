"""message_text.canonical, the comparison of the C twins' messages with Python's: it forgives the spelling of a
number or of an exception, nothing else."""
from message_text import Message, canonical


def test_the_same_number_spelled_by_c_or_python_is_equal():
    assert canonical("parameter R = -1.0: must be > 0") == canonical("parameter R = -1: must be > 0")
    assert canonical("tau = 1000000000000000.0 and 1e-05") == canonical("tau = 1e+15 and 1e-05")
    assert canonical("x = 0.1") == canonical("x = 0.10000000000000001")  # %.17g of 0.1 reads back as 0.1
    assert canonical("x = nan, y = -inf") == canonical("x = nan, y = -inf")


def test_another_number_word_or_sign_differs():
    assert canonical("parameter R = -1.0: must be > 0") != canonical("parameter R = -1.5: must be > 0")
    assert canonical("x = 0.1") != canonical("x = 0.10000000000000002")  # the next double
    assert canonical("x = 0.0") != canonical("x = -0.0")
    assert canonical("parameter R = -1.0: must be > 0") != canonical("parameter mu = -1.0: must be > 0")
    assert canonical("parameter R = -1.0: must be > 0") != canonical("parameter R = -1.0: must be >= 0")


def test_numbers_inside_words_stay_words():
    assert canonical("lambda11 = 2") != canonical("lambda1 = 12")
    assert canonical("fmi2Error") == ("fmi2Error",)


def test_an_exception_repr_is_its_type_and_text():
    python = "doStep failed at tau = 2.0: ZeroDivisionError('float division by zero')"
    assert canonical(python) == canonical("doStep failed at tau = 2: ZeroDivisionError: float division by zero")
    assert canonical(python) != canonical("doStep failed at tau = 2: ValueError: float division by zero")
    nested = "initialisation failed: ParameterError(\"parameter R = 1e+300: it's out of range\")"
    assert canonical(nested) == canonical("initialisation failed: ParameterError: parameter R = 1e+300: it's out of "
                                          "range")


def test_overflow_error_texts_meet_only_as_out_of_range():
    c = "OverflowError: result out of range"
    for python in ("OverflowError(34, 'Numerical result out of range')",
                   "OverflowError: (34, 'Numerical result out of range')"):
        assert canonical(python) == canonical(c)
    assert canonical("OverflowError: math range error") != canonical(c)


def test_message_equality():
    assert Message("t = 2.0") == "t = 2" and Message("t = 2.0") != "t = 3"
    assert "2.0" in Message("t = 2.0")
