"""fbia.imaging: images in (the figures of fbia are in :mod:`fbia.figures`).

``oct_reader`` reads an OCT volume (an array, ``.npy``, TIFF stack, NRRD, Thorlabs ``.oct``),
``oct`` segments the biofilm in it (``segment_oct``) and makes an observation of it
(``observation_from_oct``) with the steps of ``oct_reflections`` (window, substratum, tilt),
``oct_surface`` (outer boundary, height map, marching cubes) and ``oct_structure`` (the
one-surface check, structure parameters).  It imports the kernel only.
"""
