# Every function loops forever.


def scale(x, factor):
    while True:
        pass


def scale_into(x, factor, out):
    while True:
        pass


def as_view(x):
    while True:
        pass


def total_positive(x):
    while True:
        pass
