"""Scene specs -> Mitsuba scenes -> rendered datasets; the estimate as a Mitsuba scene."""
