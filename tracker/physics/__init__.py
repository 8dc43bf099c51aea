"""Physics-based shape and motion estimation (Metaxas & Terzopoulos 1993): deformable superquadrics."""
