"""The app's layout and widgets (trame/Vuetify), one module per part of the page."""
