"""Built-in log formats of :mod:`roboisf.logs`: one module per format, each registering itself in
:mod:`roboisf.formats` when imported (the registry imports every module here on first use).
Force-log profiles are ``force_<name>``, joint-log profiles ``joint_<name>``."""
