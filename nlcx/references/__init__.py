"""Reference signals r(t), registered by name and evaluated on the sampling grid."""
