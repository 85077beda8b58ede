"""vibrofmu.analyses.bit_identity's comparison of two runs' columns (the runs themselves need built FMUs)."""
import numpy as np

from vibrofmu.analyses.bit_identity import compare, main, same_bits


def test_same_bits_tells_signed_zeros_apart_and_nan_equal():
    # == would call 0.0 and -0.0 equal and NaN unequal to itself: the bits say the opposite
    assert not same_bits(np.array([0.0]), np.array([-0.0]))
    assert same_bits(np.array([np.nan, 1.0]), np.array([np.nan, 1.0]))


def test_compare_names_new_gone_and_differing_outputs():
    t = np.array([0.0, 0.1, 0.2])
    x = np.array([1.0, 2.0, 3.0])
    old = {"time": t, "x": x, "gone": x}
    new = {"time": t, "x": np.array([1.0, 2.0, np.nextafter(3.0, 4.0)]), "added": x}
    notes = compare(old, new)
    assert "new output added" in notes and "output gone gone" in notes
    (differs,) = [note for note in notes if note.startswith("x:")]
    assert "1 points differ from t = 0.2" in differs
    assert compare(old, dict(old)) == []


def test_main_refuses_a_missing_folder(tmp_path, capsys):
    assert main([str(tmp_path), str(tmp_path / "missing")]) == 2
    assert capsys.readouterr().err.startswith("error: ")
