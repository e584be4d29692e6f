"""Fuzz targets (atheris): one module per decoder and reader; ``python -m tests.fuzz``.

Nothing of navtwin is imported here, so that the runner can import a target's modules under
atheris's instrumentation (docs/testing.md, "Fuzzing").
"""

#: target name -> module tests.fuzz.<name>
TARGETS = ("sins", "nanoloc", "xbee_api1", "xbee_api2", "xbee_sins", "recording", "scenario",
           "host_config")
