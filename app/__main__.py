"""``python -m app``: serve the app (same options as ``lmapd app``)."""

from app.main import main

raise SystemExit(main())
