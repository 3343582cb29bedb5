// placeholder: the driver comes from tests/webxr/headset.js
