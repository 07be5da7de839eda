"""Fingerprints from the model: the rolled-equivalent print of a reconstruction (``fs3d print``).

:mod:`~fingersplat3d.prints.skin_chart` unrolls the model's surface by arc length,
:mod:`~fingersplat3d.prints.rolled` textures and inks it, :mod:`~fingersplat3d.prints.enhance` filters
the ridges along their flow, :mod:`~fingersplat3d.prints.make` reads the inputs and writes the files.
"""
