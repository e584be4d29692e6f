"""What both sides share and neither owns: the declarative schema of TOML tables and the
ranges of the lab's numbers. Imports nothing of ours but :mod:`protocols`."""
