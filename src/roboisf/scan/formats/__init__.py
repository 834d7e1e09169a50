"""Built-in scan formats: one module per format, each registering a format of kind ``scan`` in
:mod:`roboisf.formats` when imported (the registry imports every module here on first use).
The reading code is :mod:`roboisf.scan.readers`."""
