// Whether the software traversal's leaf loop tests cutout geometry's opacity micro-maps: this
// module says yes. A scene without cutout geometry composes scene/cutout_test_off in its place
// (scene/traversal.rs, `library`), where the constant is false: the test, and the opacity word
// it reads on entering each BLAS, compile away, so opaque scenes trace as if cutouts did not
// exist.

const RT_CUTOUTS: bool = true;
