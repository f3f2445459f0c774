// Stands in for scene/cutout_test when the scene holds no cutout geometry: the software
// traversal compiles without the opacity test (see that module).

const RT_CUTOUTS: bool = false;
