// node serialport on one port (argv[2]): prints "open", "data" (first bytes), "close", "error ...".
// Used by tests/emulator/test_control.py when node and the serialport package are installed.
const { SerialPort } = require('serialport');
const port = new SerialPort({ path: process.argv[2], baudRate: 115200 });
let seen = false;
port.on('open', () => console.log('open'));
port.on('data', () => { if (!seen) { seen = true; console.log('data'); } });
port.on('close', () => { console.log('close'); process.exit(0); });
port.on('error', (e) => console.log('error ' + e.message));
