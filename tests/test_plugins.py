"""protocols.plugins.Registry: the one way tracks, fault kinds, commands, benchmarks and ports are
found (built in, registered in process, entry points of installed packages)."""

import pytest

from navtwin.protocols.plugins import Registry, entry_points

from .packages import install


def _check(name, obj):
    if not isinstance(obj, int):
        raise TypeError(f"{name}: {obj!r} is not an int; register an int")


@pytest.fixture
def package(tmp_path, monkeypatch):
    """An installed package declaring two entry points in the group ``navtwin.toys``."""
    install(tmp_path, monkeypatch, "toys", "[navtwin.toys]\nseven = toys:SEVEN\nword = toys:WORD\n",
            "SEVEN = 7\nWORD = 'seven'\n")


def test_names_list_built_in_then_registered_then_entry_points(package):
    reg = Registry("navtwin.toys", "toy", {"two": 2, "pi": "math:pi"}, check=_check, error=TypeError)
    reg.register("one", 1)
    assert reg.names() == ("two", "pi", "one", "seven", "word")
    assert reg.get("two") == 2 and reg.get("one") == 1 and reg.get("seven") == 7
    assert abs(reg.get("pi") - 3.14159) < 1e-5  # a built-in "module:attribute" loads when asked
    assert [ep.name for ep in entry_points("navtwin.toys")] == ["seven", "word"]


def test_a_plugin_that_fails_its_check_is_refused_with_one_line(package):
    reg = Registry("navtwin.toys", "toy", check=_check, error=TypeError)
    with pytest.raises(TypeError, match="^word: 'seven' is not an int; register an int$"):
        reg.get("word")
    with pytest.raises(TypeError, match="not an int"):
        reg.register("half", 0.5)
    assert "half" not in reg


def test_a_name_is_taken_once_and_unregister_gives_it_back():
    reg = Registry("navtwin.toys-none", "toy", {"two": 2})
    with pytest.raises(ValueError, match="toy 'two' is already registered; choose another name"):
        reg.register("two", 3)
    reg.register("three", 3)
    with pytest.raises(ValueError, match="already registered"):
        reg.register("three", 4)
    reg.unregister("three")
    assert "three" not in reg and reg.names() == ("two",)
    with pytest.raises(KeyError):
        reg.get("three")
    assert reg.unknown(["two", "nine"]) == "unknown toy 'nine'; use one of two"
    assert reg.unknown(["two"]) is None


def test_an_entry_point_that_does_not_load_names_its_package(tmp_path, monkeypatch):
    install(tmp_path, monkeypatch, "broken", "[navtwin.toys]\ngone = no_such_module_here:X\n", None)
    reg = Registry("navtwin.toys", "toy")
    with pytest.raises(ValueError, match="^entry point gone = 'no_such_module_here:X' in "
                       "navtwin.toys does not load .*; fix or uninstall the package"):
        reg.get("gone")
