"""Detect-and-track chains (task ``detect-track``): ``cfar-track`` (:mod:`.chain`)
composes a registered cell detector and a registered multi-target tracker by name
(:mod:`.compose`), with the plot extraction between them (:mod:`.plots`)."""
