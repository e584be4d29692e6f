"""What both sides share and neither owns: the declarative schema of TOML tables, the
ranges of the lab's numbers and the earth's constants. Imports nothing of ours but :mod:`navtwin.protocols`."""
