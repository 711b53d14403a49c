"""The framework every lab uses: rays, meshes, cameras, scenes, images, ray maths."""
