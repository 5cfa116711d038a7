// The emulated Raspberry Pi Pico: the RP2040 of rp2040js running a Pico firmware (a .uf2), in
// lockstep with the simulated actuator that host/link/emulated_pico/bench.py keeps in Python.
//
// Nothing here runs on its own clock. The Python side asks for a slice of emulated time; this
// process runs the chip for exactly that long and answers with what the chip did to the world
// in it (the average level of each watched output pin, how many ADC conversions it made, the
// bytes it sent over USB); the Python side advances the actuator by the same slice and answers
// with the ADC codes the next slice reads and the bytes the USB host sends. A slow emulator so
// changes nothing but the wall time.
//
// Protocol on stdin and stdout (logs go to stderr): messages of a u32 length (little endian) and a payload.
//   to Python: u8 1 | f64 t_ns | f64 instructions | f64 cycles | u8 flags (1: USB configured)
//              | 5 x u16 conversions per ADC input | n x f64 mean level of each watched pin
//              | the bytes the device sent
//   from Python: u32 slice_ns | u8 command (0 run, 1 quit) | 5 x (u16 count, count x u16 codes)
//              | the bytes the USB host sends
// Each ADC input hands out its codes in order, one per conversion, from the newest batch; an
// input that reads more often than the batch has codes wraps around (the Python side sends more
// the next time).
//
// Three things rp2040js 1.4.1 does not do by itself are done here (../shared/mcu/rp2/README.md):
// - flash erase/program: its SSI ignores SPI-flash writes, so the bootrom's flash_range_erase and
//   flash_range_program are trapped when the core reaches them and done on the flash array
//   (and written through to the filesystem image file, so a killed emulator loses nothing);
// - USB CDC OUT: it completes every armed OUT transfer after 10 us, empty when the host has
//   nothing, which keeps an idle MicroPython busy; a real host NAKs, so an armed read is held
//   until there are bytes;
// - time: emulated time advances by the cycles of each instruction at the emulated clk_sys, and
//   a sleeping core (WFI/WFE) jumps to its next alarm.
import { closeSync, openSync, readFileSync, readSync, writeSync, existsSync } from 'node:fs';
import { Simulator, USBCDC, ConsoleLogger, LogLevel } from 'rp2040js';

const FLASH_BASE = 0x10000000;
const IN_FD = 0;
const OUT_FD = 1;
const ADC_INPUTS = 5; // GPIO26-29 and the temperature sensor
const FUNCTION_PWM = 4;
const PWM_CSR_EN = 1, PWM_CSR_A_INV = 1 << 2, PWM_CSR_B_INV = 1 << 3;
const LEVEL_SAMPLE_NS = 10000; // watched pins are sampled every 10 us of emulated time

const config = JSON.parse(process.argv[2]);
const fsOffset = config.fs_offset, fsSize = config.fs_size;
const watched = config.watch_pins;

const sim = new Simulator();
const clock = sim.clock;
const mcu = sim.rp2040;
// stdout carries the protocol: everything that would print there goes to stderr
const toStderr = (...args) => process.stderr.write(args.join(' ') + '\n');
console.log = console.info = console.debug = toStderr;
// rp2040js warns on every access to what it does not emulate (the second core's FIFO, which the
// firmware touches at each soft reset): each warning once is enough
const warned = new Set();
console.warn = (...args) => { const text = args.join(' '); if (!warned.has(text)) { warned.add(text); toStderr(text); } };
mcu.logger = new ConsoleLogger(LogLevel.Error, false);
mcu.loadBootrom(new Uint32Array(new Uint8Array(readFileSync(new URL('./bootrom-b1.bin', import.meta.url))).buffer));
let broke = null;
mcu.onBreak = (code) => { broke = 'BKPT ' + code + ' at PC 0x' + mcu.core.PC.toString(16); };

function loadUF2(path) {
  const buf = readFileSync(path);
  let blocks = 0;
  for (let off = 0; off + 512 <= buf.length; off += 512) {
    const dv = new DataView(buf.buffer, buf.byteOffset + off, 512);
    if (dv.getUint32(0, true) !== 0x0a324655 || dv.getUint32(4, true) !== 0x9e5d5157) continue;
    const addr = dv.getUint32(12, true), size = dv.getUint32(16, true);
    if (addr < FLASH_BASE || addr + size > FLASH_BASE + fsOffset) {
      throw new Error(`${path}: a block at 0x${addr.toString(16)} lies outside the firmware's part of the flash`);
    }
    mcu.flash.set(buf.subarray(off + 32, off + 32 + size), addr - FLASH_BASE);
    blocks++;
  }
  if (!blocks) throw new Error(`${path} holds no UF2 blocks`);
}

loadUF2(config.uf2);
// The filesystem part of the flash: an erased chip (all 0xFF) or the image file, written through.
mcu.flash.fill(0xff, fsOffset, fsOffset + fsSize);
let imageFd = null;
if (config.fs_image) {
  if (existsSync(config.fs_image)) {
    const img = readFileSync(config.fs_image);
    mcu.flash.set(img.subarray(0, fsSize), fsOffset);
  }
  imageFd = openSync(config.fs_image, existsSync(config.fs_image) ? 'r+' : 'w+');
  writeSync(imageFd, mcu.flash, fsOffset, fsSize, 0);
}

function romFunction(code) {
  const rom = new Uint8Array(mcu.bootrom.buffer);
  const half = (a) => rom[a] | (rom[a + 1] << 8);
  for (let p = half(0x14); half(p); p += 4) {
    if (rom[p] === code.charCodeAt(0) && rom[p + 1] === code.charCodeAt(1)) return half(p + 2) & ~1;
  }
  throw new Error('bootrom function not found: ' + code);
}
const ROM_ERASE = romFunction('RE'), ROM_PROGRAM = romFunction('RP');
const flashOps = { erase: 0, program: 0 };

function writeThrough(start, end) {
  if (imageFd === null) return;
  const a = Math.max(start, fsOffset), b = Math.min(end, fsOffset + fsSize);
  if (b > a) writeSync(imageFd, mcu.flash, a, b - a, a - fsOffset);
}

function flashCall(pc) {
  const r = mcu.core.registers;
  if (pc === ROM_ERASE) { // flash_range_erase(addr, count, block_size, block_cmd)
    const addr = r[0] >>> 0, count = r[1] >>> 0;
    const start = addr & ~0xfff, end = (addr + count + 0xfff) & ~0xfff;
    mcu.flash.fill(0xff, start, end);
    writeThrough(start, end);
    flashOps.erase++;
  } else { // flash_range_program(addr, data, count): NOR flash only clears bits
    const addr = r[0] >>> 0, data = r[1] >>> 0, count = r[2] >>> 0;
    for (let i = 0; i < count; i++) mcu.flash[addr + i] &= mcu.readUint8(data + i);
    writeThrough(addr, addr + count);
    flashOps.program++;
  }
  mcu.core.PC = r[14] & ~1; // return to the caller (bx lr)
}

if (config.bootsel_pullup) {
  // CircuitPython senses the BOOTSEL button at boot (it floats the flash's chip select and reads
  // SIO GPIO_HI_IN bit 1) and waits while it reads low; rp2040js leaves the QSPI pad inputs low.
  // Pull QSPI_SS high as the board's 10k pull-up does (../shared/mcu/rp2/circuitpython/README.md).
  mcu.qspi[1].setInputValue(true);
  const sio = mcu.sio, sioRead = sio.readUint32.bind(sio);
  sio.readUint32 = (offset) => offset === 0x008 ? (sioRead(offset) | 2) : sioRead(offset);
}

mcu.core.PC = FLASH_BASE; // boot2 at the start of flash, as the bootrom would jump there

// ---- USB CDC: the host side of the USB serial port ----
const cdc = new USBCDC(mcu.usbCtrl);
let configured = false;
cdc.onDeviceConnected = () => { configured = true; };
let fromDevice = [];
cdc.onSerialData = (data) => { fromDevice.push(Buffer.from(data)); };
let toDevice = Buffer.alloc(0);
const usb = mcu.usbCtrl, completeRead = usb.onEndpointRead;
// One held read is enough: MicroPython's TinyUSB arms the CDC OUT endpoint single-buffered, one
// transfer at a time (a double-buffered endpoint would arm two, and the second would be lost here)
let heldRead = null;
usb.onEndpointRead = (ep, size) => {
  if (ep === cdc.outEndpoint && cdc.txFIFO.empty && toDevice.length === 0) {
    heldRead = [ep, size]; // a real host NAKs until it has something to send
    return;
  }
  completeRead(ep, size);
};
function feedDevice() {
  const fifo = cdc.txFIFO;
  let n = 0;
  while (n < toDevice.length && !fifo.full) fifo.push(toDevice[n++]);
  if (n) toDevice = toDevice.subarray(n);
  if (heldRead && !fifo.empty) {
    const [ep, size] = heldRead;
    heldRead = null;
    completeRead(ep, size);
  }
}

// ---- ADC: each conversion takes the next code of its input's batch ----
const codes = Array.from({ length: ADC_INPUTS }, () => new Uint16Array([0]));
const nextCode = new Int32Array(ADC_INPUTS);
const conversions = new Int32Array(ADC_INPUTS);
const adc = mcu.adc, startConversion = adc.onADCRead;
adc.onADCRead = (input) => {
  const batch = codes[input];
  adc.channelValues[input] = batch[nextCode[input] % batch.length];
  nextCode[input]++;
  conversions[input]++;
  startConversion(input);
};

// ---- watched output pins: the level the H-bridge sees, averaged over the slice ----
function pinLevel(n) {
  const pin = mcu.gpio[n];
  if (!pin.outputEnable) return 0; // an undriven input: the bridge's pull-down holds it low
  if (pin.functionSelect === FUNCTION_PWM) {
    const ch = mcu.pwm.channels[(n >> 1) & 7];
    if (ch.csr & PWM_CSR_EN) {
      const b = n & 1;
      const cc = b ? ch.cc >>> 16 : ch.cc & 0xffff;
      let duty = Math.min(1, cc / (ch.top + 1));
      if (ch.csr & (b ? PWM_CSR_B_INV : PWM_CSR_A_INV)) duty = 1 - duty;
      return duty;
    }
  }
  return pin.outputValue ? 1 : 0; // SIO, or a stopped PWM slice holding its last level
}
const levelSum = new Float64Array(watched.length);
const levelNow = new Float64Array(watched.length);
function sampleLevels(dt) {
  for (let i = 0; i < watched.length; i++) {
    levelSum[i] += levelNow[i] * dt;
    levelNow[i] = pinLevel(watched[i]);
  }
}

// ---- running ----
let instructions = 0, cycles = 0;
function run(sliceNs) {
  const core = mcu.core;
  const end = clock.nanos + sliceNs;
  levelSum.fill(0);
  let lastSample = clock.nanos, nextSample = lastSample + LEVEL_SAMPLE_NS;
  while (clock.nanos < end && broke === null) {
    const now = clock.nanos;
    if (now >= nextSample) {
      sampleLevels(now - lastSample);
      lastSample = now;
      nextSample = now + LEVEL_SAMPLE_NS;
      if (toDevice.length || heldRead) feedDevice();
    }
    const cycleNanos = 1e9 / mcu.clkSys;
    if (core.waiting) {
      let dt = clock.nextAlarm ? clock.nanosToNextAlarm : end - now;
      dt = Math.min(Math.max(dt, cycleNanos), end - now, nextSample - now);
      clock.tick(dt);
    } else {
      const pc = core.PC;
      if (pc === ROM_ERASE || pc === ROM_PROGRAM) {
        flashCall(pc);
        clock.tick(1000);
        continue;
      }
      const c = core.executeInstruction();
      instructions++;
      cycles += c;
      clock.tick(c * cycleNanos);
    }
  }
  sampleLevels(clock.nanos - lastSample);
  const span = clock.nanos - (end - sliceNs);
  for (let i = 0; i < watched.length; i++) levelSum[i] = span > 0 ? levelSum[i] / span : levelNow[i];
}

// ---- the lockstep protocol ----
function readExactly(n) {
  const buf = Buffer.alloc(n);
  let got = 0;
  while (got < n) {
    let k;
    try {
      k = readSync(IN_FD, buf, got, n - got, null);
    } catch (e) {
      if (e.code === 'EAGAIN') continue;
      throw e;
    }
    if (k === 0) return null; // the Python side is gone
    got += k;
  }
  return buf;
}

function writeAll(buf) {
  let off = 0;
  while (off < buf.length) {
    try {
      off += writeSync(OUT_FD, buf, off, buf.length - off);
    } catch (e) {
      if (e.code !== 'EAGAIN') throw e;
    }
  }
}

function report() {
  const out = Buffer.concat(fromDevice);
  fromDevice = [];
  const head = Buffer.alloc(1 + 8 * 3 + 1 + 2 * ADC_INPUTS + 8 * watched.length);
  let o = head.writeUInt8(1, 0);
  o = head.writeDoubleLE(clock.nanos, o);
  o = head.writeDoubleLE(instructions, o);
  o = head.writeDoubleLE(cycles, o);
  o = head.writeUInt8(configured ? 1 : 0, o);
  for (let i = 0; i < ADC_INPUTS; i++) o = head.writeUInt16LE(Math.min(conversions[i], 65535), o);
  for (let i = 0; i < watched.length; i++) o = head.writeDoubleLE(levelSum[i], o);
  const len = Buffer.alloc(4);
  len.writeUInt32LE(head.length + out.length, 0);
  writeAll(Buffer.concat([len, head, out]));
  conversions.fill(0);
}

function serve() {
  for (let i = 0; i < watched.length; i++) levelNow[i] = pinLevel(watched[i]);
  report(); // time 0: the Python side answers with the first slice
  for (;;) {
    const lenBuf = readExactly(4);
    if (lenBuf === null) break;
    const msg = readExactly(lenBuf.readUInt32LE(0));
    if (msg === null) break;
    let o = 0;
    const sliceNs = msg.readUInt32LE(o); o += 4;
    const command = msg.readUInt8(o); o += 1;
    for (let i = 0; i < ADC_INPUTS; i++) {
      const n = msg.readUInt16LE(o); o += 2;
      if (n) {
        codes[i] = new Uint16Array(n);
        for (let k = 0; k < n; k++) { codes[i][k] = msg.readUInt16LE(o); o += 2; }
        nextCode[i] = 0;
      }
    }
    if (o < msg.length) toDevice = Buffer.concat([toDevice, msg.subarray(o)]);
    if (command === 1) break;
    if (toDevice.length) feedDevice();
    run(sliceNs);
    if (broke !== null) {
      process.stderr.write(`emulated Pico stopped: ${broke}\n`);
      process.exitCode = 3;
      break;
    }
    report();
  }
  if (imageFd !== null) closeSync(imageFd);
}

serve();
