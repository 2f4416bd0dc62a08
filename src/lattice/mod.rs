//! The coarse interior lattice: hexahedral cells, B-spline bases, superimposed elements, embedding.
