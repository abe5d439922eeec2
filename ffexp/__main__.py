"""``python -m ffexp`` is the ``ffexp`` command."""

from ffexp.cli import main

main()
