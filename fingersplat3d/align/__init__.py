"""Registration: ``correspond`` finds correspondences between views, ``solve`` turns them into cameras and
surfaces, ``register`` drives both; ``transfer`` carries pixels between views through a reconstruction."""
