"""The scene room: what a scene is and where scenes come from.

``bodies`` (bodies, supports, the scene, its validation), ``shapes`` (every shape's geometry),
``limits`` (the bounds every input is held to), ``format`` (the JSON scene format /2 and /1),
``files`` (scene files by extension, the paper's CSV), ``schema`` (the format's JSON Schema),
``examples`` (the packaged scenes), ``catalogue``, ``generators`` and ``zoo`` (scenes made here:
random scenes, towers and tables, the zoo's families), ``disjoint`` (union-find, for support graphs),
``meshes`` (objects from mesh files: read, decomposed into convex parts, cached; where a scene may
read them), ``household`` (cups and bowls as closed meshes).
Nothing here simulates: the scene is data, checked once.
"""
