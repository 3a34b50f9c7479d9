//! Radiative transfer: PROSPECT-D leaf optics, 4SAIL canopy, INFORM forest, Sentinel-2 bands.
