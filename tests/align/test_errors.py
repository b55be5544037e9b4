"""align's errors: library messages name the value (the CLI adds the flag), results travel with the error."""
import pickle

import numpy as np
import pytest

from align.errors import AlignError, OptionError, ShapeError, ShiftRangeError, UnobservableError
from align.pipeline import AlignOptions
from align.roi import foreground_mask
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform
from tests.conftest import assert_one_line_error


@pytest.mark.parametrize("field,value", [("shift_range_ms", -1.0), ("probes", 2), ("association", "closest"),
                                         ("time_model", "cubic"), ("max_dt_ms", 0.0), ("features", "surf")])
def test_option_errors_name_the_option_not_the_flag(field, value):
    with pytest.raises(OptionError) as info:
        AlignOptions(**{field: value}).check()
    assert info.value.option == field
    shown = f"{value:g}" if isinstance(value, float) else str(value)
    assert "--" not in str(info.value) and shown in str(info.value)


def test_cli_adds_the_flag(cli, tmp_path):
    r = cli("align", str(tmp_path / "none"), "--out", str(tmp_path / "a"), "--probes", "2")
    assert_one_line_error(r, "--probes", "at least 3, got 2")
    assert not (tmp_path / "a").exists()


def test_bad_arrays_are_align_errors_and_value_errors():
    K = Intrinsics(16, 12, 20.0, 20.0, 7.5, 5.5)
    for call in (lambda: DepthWarper(K, K, Transform.identity())(np.zeros((5, 5), np.float32)),
                 lambda: foreground_mask(np.zeros((4, 4)), np.zeros((3, 3)))):
        with pytest.raises(ShapeError) as info:
            call()
        assert isinstance(info.value, AlignError) and isinstance(info.value, ValueError)
    with pytest.raises(OptionError, match="engine"):
        DepthWarper(K, K, Transform.identity(), engine="cuda")


def test_the_estimate_travels_with_the_error_even_across_processes():
    for cls in (ShiftRangeError, UnobservableError):
        err = cls("time shift unobservable: static", estimate={"a_us": 12.0})
        assert err.estimate == {"a_us": 12.0}
        back = pickle.loads(pickle.dumps(err))
        assert type(back) is cls and str(back) == str(err) and back.estimate == {"a_us": 12.0}
    assert ShiftRangeError("edge").option == "shift_range_ms"
