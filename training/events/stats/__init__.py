"""Statistics that fit the synthetic source: real tracks, the project's detector, the players stage."""
