"""The pure star-identification engine: numpy, scipy and OpenCV only.

Nothing here imports FastAPI, pydantic, httpx or the ``client`` package (a test pins it).
"""
