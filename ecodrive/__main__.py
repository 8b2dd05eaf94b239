"""``python -m ecodrive``: same as the ``ecodrive`` command."""

from ecodrive.cli import main

raise SystemExit(main())
