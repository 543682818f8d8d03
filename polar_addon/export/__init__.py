"""Blender depsgraph → engine Scene.  Each module converts one kind of data; ``scene.export_scene``
ties them together and collects warnings for the user (never silently wrong output)."""
