"""How numbers are written for people (batch.present.fmt)."""

from batch.present import fmt


def test_p_values():
    assert fmt.p_value(0.012345) == "0.0123" and fmt.p_value(0.0) == "< 1e-300"
    assert fmt.p_value(None) == fmt.p_value(float("nan")) == "n/a"
    assert fmt.p_is(0.5) == "= 0.5" and fmt.p_is(0.0) == "< 1e-300"


def test_percentages():
    assert fmt.percent(0.0123) == "+1.23 %" and fmt.percent(-0.5, 1) == "-50.0 %"
    assert fmt.percent(None) == fmt.percent(float("inf")) == "n/a"


def test_a_bound_above_zero_is_never_written_as_zero():
    """'a bias beyond 0.00 % is ruled out' said of passes that differ only by float rounding: the bound is above 0,
    so it is written as the smallest size shown, which it is below."""
    assert fmt.bound(3e-9) == fmt.bound(4.9e-5) == "0.01 %" and fmt.bound(0.0) == "0.00 %"
    assert fmt.bound(0.0082) == fmt.magnitude(0.0082) == "0.82 %" and fmt.bound(None) == "—"


def test_durations():
    assert fmt.duration(None) == fmt.duration(float("nan")) == fmt.duration(-1) == "?"
    assert fmt.duration(0.64) == "0.6 s" and fmt.duration(9.96) == "10 s"
    assert fmt.duration(42.4) == "42 s"
    assert fmt.duration(125) == "2 min 05 s"
    assert fmt.duration(7300) == "2 h 01 min"


def test_one_line():
    assert fmt.one_line("a\n  b\tc") == "a b c"
    assert len(fmt.one_line("x" * 500)) == fmt.ONE_LINE_LENGTH
