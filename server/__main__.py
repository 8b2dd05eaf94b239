"""``python -m server``: same as ``ecodrive serve``."""

from server.main import main

raise SystemExit(main())
