"""Physical accuracy: the textile world's standard tests with their exact answers.

`elastica` (the exact heavy elastica of the ASTM D1388 cantilever), `strips` (test specimens
meshed three ways), `settle` (bring a specimen to rest), `cantilever`, `tensile` and `cusick`
(the scenes and what they measure), `swing` (a hanging strip's first mode against the exact
heavy chain, in motion), `charts`, `cli` (`cloth-mg materials` and the scenes of
`cloth-mg run`). The measured fabrics live in `physics.fabrics`.
"""
