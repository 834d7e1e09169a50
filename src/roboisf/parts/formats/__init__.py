"""Built-in part kinds (``[part] kind``): one module per kind, each registering a format of kind
``part`` in :mod:`roboisf.formats` when imported (the registry imports every module here on
first use)."""
