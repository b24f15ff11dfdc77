"""``python -m nlcx.cli``."""

from nlcx.cli import main

main()
