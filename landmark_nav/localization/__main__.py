"""``python -m landmark_nav.localization [--seeds 1-10]``: print the hallway study."""

from .evaluate import main

raise SystemExit(main())
