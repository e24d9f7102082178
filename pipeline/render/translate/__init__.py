"""A scene's records translated to Mitsuba: each object's role, shapes, materials and
lights as Mitsuba dictionaries, the disk cache of converted assets, records at one
instant, deforming meshes' templates, and the scalar fallback's whole scenes."""
