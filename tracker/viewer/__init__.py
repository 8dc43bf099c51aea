"""The browser viewer (viser): the body, the cameras, the edges; review, live tracking and manual placement."""
