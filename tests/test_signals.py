"""A signal swallowed by a library still ends a render at the next pass."""

import pytest
from translucent import signals
from translucent.reference.render import render
from translucent.scenes import load_scene


@pytest.fixture(autouse=True)
def _clean():
    signals.reset()
    yield
    signals.reset()


@pytest.mark.parametrize("kind, error", [("interrupt", KeyboardInterrupt),
                                         ("terminate", signals.Terminated)])
def test_a_recorded_signal_stops_the_render_before_its_next_pass(kind, error):
    signals.record(kind)
    with pytest.raises(error):
        render(load_scene("furnace_sphere"), spp=1, passes=2, cache=False, progress=False)


def test_without_a_signal_check_does_nothing():
    signals.check()
    image = render(load_scene("furnace_sphere"), spp=1, passes=2, cache=False,
                   progress=False)
    assert image.rgb.shape[-1] == 3
