"""Build recipes (TOML) shipped with cutkit; see ``cutkit build-model --recipe``."""
