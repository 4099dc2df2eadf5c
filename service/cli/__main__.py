"""``python -m service.cli``: the ``skyfix`` command."""

from . import main

main()
