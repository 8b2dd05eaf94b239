// Spoken advice: the browser's own voice (Web Speech API) in the page's language; the service's WAV
// (GET /v1/trips/{id}/advice.wav, espeak-ng) where the browser has no speech or its voice fails.

const START_WATCHDOG_S = 3; // a Web Speech utterance that has neither started nor failed by then: use the WAV

/** A 10 ms silent WAV, played inside the user's tap so that later plays are allowed (iOS, autoplay rules). */
function silentWavUrl() {
  const samples = 80;
  const bytes = new DataView(new ArrayBuffer(44 + 2 * samples));
  const text = (offset, s) => [...s].forEach((c, i) => bytes.setUint8(offset + i, c.charCodeAt(0)));
  text(0, "RIFF"); bytes.setUint32(4, 36 + 2 * samples, true); text(8, "WAVE");
  text(12, "fmt "); bytes.setUint32(16, 16, true); bytes.setUint16(20, 1, true); bytes.setUint16(22, 1, true);
  bytes.setUint32(24, 8000, true); bytes.setUint32(28, 16000, true); bytes.setUint16(32, 2, true); bytes.setUint16(34, 16, true);
  text(36, "data"); bytes.setUint32(40, 2 * samples, true);
  return URL.createObjectURL(new Blob([bytes], { type: "audio/wav" }));
}

/** A short two-tone chime (880 then 660 Hz, 0.3 s), for an alert when the browser has no voice of its own. */
function chimeWavUrl() {
  const rate = 8000;
  const samples = Math.round(0.3 * rate);
  const bytes = new DataView(new ArrayBuffer(44 + 2 * samples));
  const text = (offset, s) => [...s].forEach((c, i) => bytes.setUint8(offset + i, c.charCodeAt(0)));
  text(0, "RIFF"); bytes.setUint32(4, 36 + 2 * samples, true); text(8, "WAVE");
  text(12, "fmt "); bytes.setUint32(16, 16, true); bytes.setUint16(20, 1, true); bytes.setUint16(22, 1, true);
  bytes.setUint32(24, rate, true); bytes.setUint32(28, 2 * rate, true); bytes.setUint16(32, 2, true); bytes.setUint16(34, 16, true);
  text(36, "data"); bytes.setUint32(40, 2 * samples, true);
  for (let i = 0; i < samples; i += 1) {
    const f = i < samples / 2 ? 880 : 660;
    const fade = Math.min(1, i / 80, (samples - i) / 80);
    bytes.setInt16(44 + 2 * i, Math.round(12000 * fade * Math.sin((2 * Math.PI * f * i) / rate)), true);
  }
  return URL.createObjectURL(new Blob([bytes], { type: "audio/wav" }));
}

export class Speaker {
  /** `wav()` resolves to a Response with the current advice as WAV (the trip's audio link). */
  constructor({ lang, onState = () => {} }) {
    this.lang = lang;
    this.onState = onState;
    this.muted = false;
    this.wav = null;
    this.webSpeech = typeof window.speechSynthesis?.speak === "function" && typeof window.SpeechSynthesisUtterance === "function";
    this.audio = typeof Audio === "function" ? new Audio() : null;
    this.objectUrl = null;
    this.voice = null;
    this.current = null;
    if (this.webSpeech) {
      const pick = () => {
        const voices = speechSynthesis.getVoices();
        const base = this.lang.split("-")[0].toLowerCase();
        this.voice = voices.find((v) => v.lang.toLowerCase() === this.lang.toLowerCase())
          ?? voices.find((v) => v.lang.toLowerCase().split(/[-_]/)[0] === base) ?? null;
      };
      pick();
      speechSynthesis.addEventListener?.("voiceschanged", pick);
    }
  }

  get engine() {
    return this.webSpeech ? "browser voice" : this.audio ? "service voice" : "no voice";
  }

  /** Call inside the user's tap (Start): browsers only let a page speak or play sound after a gesture. */
  unlock() {
    if (this.webSpeech) speechSynthesis.speak(new SpeechSynthesisUtterance(""));
    if (this.audio) {
      this.audio.src = silentWavUrl();
      this.audio.play().catch(() => {});
    }
  }

  setMuted(muted) {
    this.muted = muted;
    if (muted) this.stop();
  }

  stop() {
    if (this.webSpeech) speechSynthesis.cancel();
    this.audio?.pause();
  }

  /** Say `text` now, cutting off whatever is still being said (only the latest advice matters); without a
   * working browser voice, `fallback()` (default: the service's WAV of the trip's latest advice). */
  say(text, fallback = () => this.playWav()) {
    if (this.muted || !text) return;
    if (!this.webSpeech) {
      fallback();
      return;
    }
    const utterance = new SpeechSynthesisUtterance(text);
    utterance.lang = this.lang;
    if (this.voice) utterance.voice = this.voice;
    let settled = false; // started, ended or failed
    const fail = (why) => {
      if (!this.webSpeech) return;
      this.webSpeech = false; // this browser's voice does not work: the service's from now on
      this.onState(`browser voice failed (${why}); using the service's voice`);
      fallback();
    };
    utterance.onstart = () => { settled = true; };
    utterance.onend = () => { settled = true; };
    utterance.onerror = (event) => {
      settled = true;
      if (!["interrupted", "canceled"].includes(event.error)) fail(event.error);
    };
    this.current = utterance;
    speechSynthesis.cancel();
    speechSynthesis.speak(utterance);
    setTimeout(() => {
      if (!settled && this.current === utterance) fail("it did not start");
    }, START_WATCHDOG_S * 1000);
  }

  /** Say `text` without the service (it may be the one that is gone): the browser's voice, else a chime. */
  alert(text) {
    this.say(text, () => {
      if (!this.audio || this.muted) return;
      this.audio.src = chimeWavUrl();
      this.audio.play().catch(() => {});
    });
  }

  async playWav() {
    if (!this.audio || !this.wav || this.muted) return;
    try {
      const response = await this.wav();
      if (!response.ok) {
        const body = await response.json().catch(() => ({}));
        this.onState(`no voice: ${body.message ?? `HTTP ${response.status}`}`);
        return;
      }
      const blob = await response.blob();
      if (this.objectUrl) URL.revokeObjectURL(this.objectUrl);
      this.objectUrl = URL.createObjectURL(blob);
      this.audio.src = this.objectUrl;
      await this.audio.play();
    } catch (error) {
      if (error.name !== "AbortError") this.onState(`no voice: ${error.message}`); // AbortError: stopped or replaced
    }
  }
}
