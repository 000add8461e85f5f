"""The on-disk formats: datasets, runs, meshes, EXR and images; atomic output folders."""
