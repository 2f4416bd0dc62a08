//! Pictures a person looks at: charts (PNG) of measurements and software-rendered preview
//! images of meshes (shaded, or coloured by a per-vertex quantity such as wrinkle depth),
//! composed side by side or as a contact sheet. No GPU and no system fonts: text uses the
//! shipped DejaVu Sans ([`font`]). All output is deterministic and written atomically.

pub mod contour;
pub mod font;
pub mod pareto;
pub mod plot;
