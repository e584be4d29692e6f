"""Fuzz target: the host config reader (host.config.load) on a TOML file whose text is the
input; a config it accepts must come back exactly through to_dict and from_dict (which a
host recording's meta relies on)."""
from navtwin.host.config import CONFIG_DIR, ConfigError, HostConfig, from_dict, load

from .harness import check_reader

NAME = "fuzz.toml"
SEEDS = [p.read_bytes() for p in sorted(CONFIG_DIR.glob("*.toml"))] + \
    [b"[[anchors]]\nid = 1\nx = 0\ny = 0\n[filters]\nrange_bias_m = {1 = 0.3}\n[filters.ukf]\n"
     b"alpha = 1.0\n",
     # tomllib's limits: nesting past the recursion limit, an integer past 4300 digits
     b"[timing]\nhold_s = " + b"{a = " * 2000, b"[[anchors]]\nid = " + b"1" * 4400]


def verify(config: HostConfig, _directory) -> None:
    assert from_dict(config.to_dict(), "to_dict") == config


def check(data: bytes) -> None:
    check_reader(lambda d: load(str(d / NAME)), ConfigError, {NAME: data}, verify)
