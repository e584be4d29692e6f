"""The lab: both sides together. Evaluation against the emulator's truth (``evaluate``), the
orchestrated lab run (``orchestrator``), the in-memory run of the world into the host's
pipeline (``run``), the live soak (``soak``) and the benchmarks that need both sides
(``bench``). May import protocols, common, emulator and host; neither side imports it.
"""
