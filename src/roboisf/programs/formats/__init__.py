"""The built-in toolpath/program formats, one module each; every module registers its format
with :func:`roboisf.programs.registry.register` when imported (the registry imports them all on
first use). A new format is a new module here — see ``docs/extending.md``."""
