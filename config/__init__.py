"""The shipped default configuration (installed as ``servotau.defaults``; data files only).

Found at run time through importlib.resources (:func:`servotau.config.default_config_dir`);
``servotau config init DIR`` copies it into an editable folder.
"""
