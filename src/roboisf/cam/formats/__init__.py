"""Built-in CAM/CNC formats of :mod:`roboisf.cam`: one module per format, each registering itself
in :mod:`roboisf.formats` when imported (the registry imports every module here on first use).
CAM program formats are ``cam_<name>``."""
