"""The headless commands (docs/cli.md): thin layers over insitu.services."""
