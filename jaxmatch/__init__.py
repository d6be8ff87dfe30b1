"""jaxmatch: pick the best quadrilateral mesh from a catalogue for a planar shape.

Method: Surynkova, "Selecting the Best Quadrilateral Mesh for Given Planar Shape"
(weighted longest-common-subsequence between the shape's s/x/v annotation and the
mesh boundary's valence triples, scored by lattices).
"""

__version__ = "0.1.0"
