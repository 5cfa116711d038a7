"""`python -m host` is the same as the `host` console script."""

from host.cli import main

raise SystemExit(main())
