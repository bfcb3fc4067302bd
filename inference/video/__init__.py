"""What the video shows besides the ball: camera cuts and court views (:mod:`.scenes`), static overlays such as a
scoreboard or a logo (:mod:`.masks`)."""
