# Every function and class of Lab 0 loops forever.


def _hang(*args, **kwargs):
    while True:
        pass


def __getattr__(name):
    if name.startswith("_"):
        raise AttributeError(name)
    return _hang
