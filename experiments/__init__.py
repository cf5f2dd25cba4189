"""Scripts (one thin ``main`` each, ``python -m experiments.<name> --help``) over
the ``pipeline`` library and the ``studies`` built on it."""
