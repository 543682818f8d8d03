"""Errors raised for bad user input (the lowest layer: every package may raise it).

Every message names the offending field with a JSON-style path
(``objects[2].transform.scale``) and states the allowed range, so that the
CLI and Blender can show it as is, without a traceback.
"""


class SceneError(ValueError):
    """Invalid scene, parameter or input file.

    ``field`` is the path of the offending value (may be empty for whole-file
    problems); ``str(err)`` is a complete, user-facing sentence.
    """

    def __init__(self, field: str, message: str):
        self.field = field
        self.reason = message
        super().__init__(f"{field}: {message}" if field else message)
