"""What a board's /main.py runs: build the App from the board and calibration files, serve the link.

A board's /main.py is two lines:

    from firmware.board_main import run
    run("board.json", "calibration.json")

The motor is off on every way out (normal return, Ctrl-C from mpremote, any exception): App.run
promises it, and `run` stops the App again in `finally` in case construction or the link failed.
"""

from firmware.link import Link


def run(board_path="board.json", calibration_path="calibration.json", machine=None):
    from firmware.app import App

    app = None
    try:
        app = App(board_path, calibration_path, machine=machine)
        link = Link(app)
        link.hello()
        app.run(link)
    finally:
        if app is not None:
            app.stop()
