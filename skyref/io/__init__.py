"""Reading and writing skies: EXR (spectral layout + RGB preview), PNG previews, datasets."""
