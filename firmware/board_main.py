"""What a board's /main.py runs: build the App from the board and calibration files, serve the link.

A board's /main.py is two lines:

    from firmware.board_main import run
    run("board.json", "calibration.json")

Before the App loads the calibration, a calibration left aside by an interrupted install is put
back (recover_calibration). The motor is off on every way out (normal return, Ctrl-C from mpremote, any exception): App.run
promises it, and `run` stops the App again in `finally` in case construction or the link failed.
App.run records why it ended in `last_exit.txt` (beside main.py); the next boot reads it back
into status()["last_exit"]. Parameters kept with the `save` command live in `params.txt`
(firmware/saved_params.py) and are loaded at boot. On CircuitPython both are slots of
microcontroller.nvm instead, named nvm:last_exit.txt and nvm:params.txt (hal.record).
"""

import os


def recover_calibration(path):
    """Finish an install that stopped between moving the old calibration aside and moving the
    new one in (only possible on FAT, see host/link/flashing.py): put the old one back."""
    from firmware.records import exists

    old = path + ".old"
    if not exists(path) and exists(old):
        os.rename(old, path)


def run(board_path="board.json", calibration_path="calibration.json", machine=None, exit_path="last_exit.txt",
        params_path="params.txt"):
    from firmware.protocol import BOOTING

    print(BOOTING)  # before the slow part: a host waits for the hello instead of resetting again
    # imported only now: CircuitPython compiles the source on the board (a second and more of
    # an emulated Pico's time before the line above, with these at the top)
    from firmware.app import App
    from firmware.hal import console_stream, record
    from firmware.link import Link

    app = None
    try:
        recover_calibration(calibration_path)
        app = App(board_path, calibration_path, machine=machine, exit_record=record(exit_path),
                  params_record=record(params_path))
        link = Link(app, *console_stream())
        link.hello()
        app.run(link)
    finally:
        if app is not None:
            app.stop()
