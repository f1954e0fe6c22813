"""``python -m app``: serve the app (same options as ``lmapd app``)."""

from app.server.versions import FrameworkVersionError, check_framework_versions

try:
    check_framework_versions()  # before the patches (app.server.security, .sync) are imported
except FrameworkVersionError as exc:
    raise SystemExit(f"python -m app: {exc}") from None

from app.main import main

raise SystemExit(main())
