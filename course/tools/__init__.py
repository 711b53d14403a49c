"""rtcourse and what it builds: the handout, the Gradescope zip, slides, the gallery."""
