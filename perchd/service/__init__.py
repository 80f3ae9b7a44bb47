"""`perchd serve`: the systemd service, its TOML configuration and its control socket."""
