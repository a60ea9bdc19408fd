"""Grain outlines in 2-D: images, contours and their Fourier-descriptor spectra."""
