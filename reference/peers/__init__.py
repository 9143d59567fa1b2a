"""Other renderers that check the references: Blender Cycles (:mod:`.blender`)."""
