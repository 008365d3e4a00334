"""The headless commands (shared/spec/cli.md): thin layers over insitu.services."""
