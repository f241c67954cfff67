"""Camera presets shipped as TOML files (the paper's simulation and experiment setups)."""
