"""What both sides share and neither owns: the declarative schema of TOML tables, the
ranges of the lab's numbers, the lab's defaults (site, alignment, start), the earth's
constants and the installed packages' entry points.
Imports nothing of ours but :mod:`navtwin.protocols`."""
