"""The `host` commands: errors, options, platforms, the fit and bench commands, and the host's layers."""
