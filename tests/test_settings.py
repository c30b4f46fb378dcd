"""One settings vocabulary: the command line, the core and Blender's enum all take the methods from core/settings.py."""
import pytest

from gs_ibl_addon.core import settings
from gs_ibl_addon.core.bake import ProbeSettings, check_settings
from gs_ibl_addon.core.probe.filters import METHODS


def _method_choices() -> tuple:
    from gs_ibl_addon.cli import build_parser
    parser = build_parser()
    bake = next(a for a in parser._subparsers._group_actions[0].choices.values() if any(
        "--method" in x.option_strings for x in a._actions))
    return tuple(next(x for x in bake._actions if "--method" in x.option_strings).choices)


def test_every_method_name_runs_a_filter():
    assert set(settings.METHOD_ALIASES.values()) <= set(METHODS) == set(settings.FILTER_METHODS)
    for name in settings.METHOD_NAMES:
        assert check_settings(ProbeSettings(method=name)) == settings.METHOD_ALIASES[name]


def test_command_line_and_blender_offer_the_same_methods():
    assert _method_choices() == settings.METHOD_NAMES
    items = settings.blender_method_items()
    assert [settings.method_from_blender(i[0]) for i in items] == list(settings.METHOD_NAMES)
    with pytest.raises(ValueError, match="auto, sh, conv, box, exact"):
        settings.method_from_blender("MAGIC")
