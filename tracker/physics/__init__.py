"""Physics-based shape and motion estimation (Metaxas & Terzopoulos 1993,
docs/method-physics.md): deformable superquadric parts (:mod:`.superquadric`), their node
kinematics and lumped mass (:mod:`.kinematics`), and point-to-point constraints held by
Baumgarte stabilisation (:mod:`.constraints`); the decoupled continuous Kalman filter
(:mod:`.kalman`) and the synthetic error experiment of Tables I-IV (:mod:`.experiment`)."""
