"""``python -m sitgen``: the command line, as the ``sitgen`` script runs it."""

from sitgen.cli import main

main()
