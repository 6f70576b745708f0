"""``python -m sitgen.cli``: the ``sitgen`` command."""

from sitgen.cli import main

main()
